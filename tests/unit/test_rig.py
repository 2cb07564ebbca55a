"""The rig's tree: validation (every error names the key), paths and chaining."""

from __future__ import annotations

import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.joints.base import tangent_basis, unit
from acs_cli.core.rig import RigTopology, hinge_point_from_nearest, rig_topology
from acs_cli.errors import InputError
from sample_data_gen.acs_sim import random_transform

CAMS = ["cam0", "cam1", "cam2", "cam3", "cam4"]
JOINTS = [
    ("r01", ["cam0", "cam1"], "rigid"),
    ("j02", ["cam0", "cam2"], "ball"),
    ("j23", ["cam2", "cam3"], "hinge"),
    ("r43", ["cam4", "cam3"], "rigid"),
]


def test_tree_order_visits_each_camera_once_after_its_parent() -> None:
    topo = rig_topology(CAMS, JOINTS, "cam0")
    steps = topo.tree_order()
    assert [s.target for s in steps] == ["cam1", "cam2", "cam3", "cam4"]
    seen = {"cam0"}
    for s in steps:
        assert s.source in seen
        seen.add(s.target)
    # r43 is written [cam4, cam3]: reaching cam4 from cam3 walks it backwards
    assert not steps[-1].forward and steps[0].forward


def test_paths_go_up_to_the_common_ancestor_and_down() -> None:
    topo = rig_topology(CAMS, JOINTS, "cam0")
    path = topo.path("cam1", "cam4")
    assert [(s.source, s.target) for s in path] == [
        ("cam1", "cam0"),
        ("cam0", "cam2"),
        ("cam2", "cam3"),
        ("cam3", "cam4"),
    ]
    assert topo.path("cam2", "cam2") == []


def _chain(topology: RigTopology, edge: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``T_cam_ref`` of every camera from one ``T_q_p`` per edge, along the tree's steps."""
    out = {topology.reference: np.eye(4)}
    for step in topology.tree_order():
        T = edge[step.joint.name]
        out[step.target] = (T if step.forward else se3.invert_transforms(T)) @ out[step.source]
    return out


def test_chained_transforms_agree_with_direct_composition(rng: np.random.Generator) -> None:
    topo = rig_topology(CAMS, JOINTS, "cam2")  # any camera can be the reference
    T_W = {c: random_transform(rng) for c in CAMS}  # T_world_cam at one instant
    edge = {
        name: se3.invert_transforms(T_W[b[1]]) @ T_W[b[0]]  # T_q_p
        for name, b, _ in JOINTS
    }
    T_ref = _chain(topo, edge)
    np.testing.assert_allclose(T_ref["cam2"], np.eye(4), atol=1e-12)
    for c in CAMS:
        want = se3.invert_transforms(T_W[c]) @ T_W["cam2"]
        np.testing.assert_allclose(T_ref[c], want, atol=1e-10)


@pytest.mark.parametrize(
    ("joints", "key", "words"),
    [
        ([*JOINTS, ("x14", ["cam1", "cam4"], "ball")], "joints.x14.between", "cycle"),
        ([*JOINTS[:3], ("r43", ["cam9", "cam3"], "rigid")], "joints.r43.between", "cam9"),
        ([*JOINTS, ("again", ["cam3", "cam2"], "ball")], "joints.again.between", "already"),
        (JOINTS[:3], "cameras.cam4", "in no joint"),
        ([*JOINTS[:3], ("r43", ["cam4", "cam3"], "slider")], "joints.r43.type", "slider"),
        ([*JOINTS[:3], ("r43", ["cam3", "cam3"], "rigid")], "joints.r43.between", "itself"),
        ([*JOINTS[:3], ("r43", ["cam4"], "rigid")], "joints.r43.between", "two cameras"),
    ],
)
def test_bad_trees_name_the_key(joints: list, key: str, words: str) -> None:
    with pytest.raises(InputError) as err:
        rig_topology(CAMS, joints, "cam0")
    assert key in err.value.message and words in err.value.message


def test_unknown_reference_is_named() -> None:
    with pytest.raises(InputError, match=r"reference\.camera"):
        rig_topology(CAMS, JOINTS, "cam7")


def _hinge(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A hinge's geometry ``(o_p, o_q, u_p, u_q)`` (12,) with ``T_q_p`` (4, 4) between its
    bodies (one articulation), and ``G`` (12, 10): its derivatives by 10 small unknowns
    (``o_p`` 3, ``o_q`` 3, each axis 2 across itself)."""
    T_q_p = random_transform(rng)
    u_p = unit(rng.normal(size=3))
    o_p = rng.normal(size=3) * 0.3
    o_q = se3.transform_points(T_q_p, o_p)
    u_q = T_q_p[:3, :3] @ u_p
    G = np.zeros((12, 10))
    G[:6, :6] = np.eye(6)
    G[6:9, 6:8], G[9:12, 8:10] = tangent_basis(u_p), tangent_basis(u_q)
    return np.concatenate([o_p, o_q, u_p, u_q]), T_q_p, G


def test_a_hinge_point_moved_along_its_axis_is_the_nearest_in_both_bodies(
    rng: np.random.Generator,
) -> None:
    g, T_q_p, _ = _hinge(rng)
    o_p, u_p, u_q = g[:3], g[6:9], g[9:]
    for side, body_point in ((0, rng.normal(size=3)), (1, rng.normal(size=3))):
        (x_p, x_q), _ = hinge_point_from_nearest(g, np.zeros((12, 12)), side, body_point)
        # one physical point, on the axis, nearest the point given
        np.testing.assert_allclose(se3.transform_points(T_q_p, x_p), x_q, atol=1e-12)
        np.testing.assert_allclose(np.cross(x_p - o_p, u_p), 0.0, atol=1e-12)
        x_b, u_b = (x_p, u_p) if side == 0 else (x_q, u_q)
        assert float((body_point - x_b) @ u_b) == pytest.approx(0.0, abs=1e-12)
    # the axis's sign does not matter (its cross-covariances turned with it)
    C = rng.normal(size=(12, 12))
    C = C @ C.T
    flip = np.diag([1.0] * 6 + [-1.0] * 6)
    y = rng.normal(size=3)
    a, Ca = hinge_point_from_nearest(g, C, 1, y)
    b, Cb = hinge_point_from_nearest(flip @ g, flip @ C @ flip, 1, y)
    np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(Ca, Cb, atol=1e-12)


def test_a_moved_hinge_points_covariance_is_its_geometrys_propagated(
    rng: np.random.Generator,
) -> None:
    """The covariance is the geometry's (point, axis and their cross-covariance) carried
    through the move: it agrees with finite differences of the point, and with the spread
    of a Monte Carlo of the geometry; far along the axis it grows with the axis's angular
    std, and copying the default point's would be wrong."""
    g, _, G = _hinge(rng)
    # the unknowns' covariance: mm on the points, 0.5 deg on the axes, strongly correlated
    sd = np.array([2e-3] * 6 + [np.radians(0.5)] * 4)
    L = np.tril(rng.normal(size=(10, 10))) + 3 * np.eye(10)
    corr = L @ L.T / np.sqrt(np.outer(np.diag(L @ L.T), np.diag(L @ L.T)))
    S = corr * np.outer(sd, sd)
    C = G @ S @ G.T
    u_q = g[9:]
    y = g[3:6] + 2.0 * u_q + np.array([0.1, -0.05, 0.2])  # in q, 2 units along the axis
    x, Cx = hinge_point_from_nearest(g, C, 1, y)
    # finite differences of the point by the 12 geometry numbers
    h = 1e-7
    J = np.stack(
        [
            (
                hinge_point_from_nearest(g + h * e, C, 1, y)[0]
                - hinge_point_from_nearest(g - h * e, C, 1, y)[0]
            ).ravel()
            / (2 * h)
            for e in np.eye(12)
        ],
        axis=1,
    )
    np.testing.assert_allclose(Cx, J @ C @ J.T, rtol=1e-6, atol=1e-14)
    # Monte Carlo: the geometry drawn from the unknowns (unit axes), the point recomputed
    draws = rng.multivariate_normal(np.zeros(10), S, size=4000)
    B_p, B_q = G[6:9, 6:8], G[9:12, 8:10]
    pts = np.array(
        [
            hinge_point_from_nearest(
                np.concatenate(
                    [g[:6] + d[:6], unit(g[6:9] + B_p @ d[6:8]), unit(g[9:] + B_q @ d[8:])]
                ),
                C,
                1,
                y,
            )[0].ravel()
            for d in draws
        ]
    )
    spread = pts.std(axis=0)
    std = np.sqrt(np.diag(Cx))
    np.testing.assert_allclose(spread, std, rtol=0.06)
    np.testing.assert_allclose(pts.mean(axis=0), x.ravel(), atol=0.1 * std.max())
    copied = np.sqrt(np.diag(C[:6, :6]))
    assert np.all(std > 1.5 * copied), (std, copied)
    # far along the axis its std is the axis's angular std (RMS, rad) times the distance
    for far in (50.0, -50.0):
        _, Cf = hinge_point_from_nearest(g, C, 1, g[3:6] + far * u_q)
        for c in (0, 1):
            rms = np.sqrt(np.trace(Cf[3 * c : 3 * c + 3, 3 * c : 3 * c + 3]))
            axis_rms = np.sqrt(np.trace(C[6 + 3 * c : 9 + 3 * c, 6 + 3 * c : 9 + 3 * c]))
            assert rms == pytest.approx(50.0 * axis_rms, rel=0.01)


def test_a_hinge_point_moved_to_where_the_data_pin_the_axis_keeps_its_small_std(
    rng: np.random.Generator,
) -> None:
    """A hinge whose best-determined point ``z`` lies 2 units along the axis from the default
    point ``o = z - 2 u``: ``o`` and ``u`` are strongly correlated. Moved back to ``z``, the
    point has ``z``'s 1 mm std across the axis: its cross-covariance with the axis cancels
    the axis's share; without it the std would be 17 mm."""
    g0, _, G = _hinge(rng)
    s0 = 2.0
    u = (g0[6:9], g0[9:])
    z = (g0[:3] + s0 * u[0], g0[3:6] + s0 * u[1])
    g = np.concatenate([z[0] - s0 * u[0], z[1] - s0 * u[1], u[0], u[1]])
    # d(o_p, o_q, u_p, u_q) by (z_p, z_q, a_p, a_q): do = dz - s0 B da, du = B da
    D = G.copy()
    D[0:3, 6:8] = -s0 * G[6:9, 6:8]
    D[3:6, 8:10] = -s0 * G[9:12, 8:10]
    S = np.diag([1e-3**2] * 6 + [np.radians(0.5) ** 2] * 4)
    C = D @ S @ D.T
    x, Cx = hinge_point_from_nearest(g, C, 1, z[1])
    np.testing.assert_allclose(x, np.stack(z), atol=1e-12)
    for c in (0, 1):
        Cc = Cx[3 * c : 3 * c + 3, 3 * c : 3 * c + 3]
        B = tangent_basis(u[c])
        np.testing.assert_allclose(B.T @ Cc @ B, 1e-6 * np.eye(2), atol=1e-15)  # across
        assert np.sqrt(np.linalg.eigvalsh(Cc)[-1]) < 1.5e-3  # along: z_q's share, at most
    no_cross = C.copy()
    no_cross[:6, 6:] = no_cross[6:, :6] = 0.0
    _, Cn = hinge_point_from_nearest(g, no_cross, 1, z[1])
    assert np.sqrt(np.linalg.eigvalsh(Cn[3:, 3:])[-1]) > 0.015
