"""The calibration report: figures (matplotlib, Agg) and the self-contained HTML page.

:mod:`acs_cli.report.figures` draws PNG figures from arrays; :mod:`acs_cli.report.html`
assembles the page. Neither reads nor writes files: :mod:`acs_cli.stages.report` does.
"""
