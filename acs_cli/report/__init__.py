"""The calibration report: a data model, its figures (matplotlib, Agg) and the HTML page.

:mod:`acs_cli.report.model` holds the report as dataclasses (sections, estimates with std
and unit, warnings, figure data); :mod:`acs_cli.report.render` draws it:
:mod:`acs_cli.report.figures` makes PNG figures from arrays and :mod:`acs_cli.report.html`
assembles the page. :mod:`acs_cli.report.verdict` holds the thresholds and the pass / check /
fail rules of the verdict, :mod:`acs_cli.report.corners` the per-corner reprojection errors.
None of them reads or writes files: :mod:`acs_cli.stages.report` does.
"""
