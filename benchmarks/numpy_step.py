"""The NumPy peer: one explicit step of warpspec's flow (DESIGN.md section 4), in float32.

    phi_t = w_N |grad phi| div(n - V) + alpha kappa |grad phi|,  then  phi *= exp(-w_P G dt)

with the same stencils as ``warpspec.kernels.flow.flow_step``: central differences,
the usual central-difference mean curvature capped at ``1/h``, ``n - V`` nonzero only at nodes
that a constraint owns (``0 <= owner < len(normals)``), and a zero normal derivative at the
border (indices clamped, here by edge padding). Everything is vectorised (views into one padded
array, no Python loop over voxels) and stays float32, as a careful NumPy user would write it.

Run it to check, once at a small size, that it agrees with warpspec's dense Warp kernel:

    python benchmarks/numpy_step.py [--resolution 24] [--device cpu]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

OCTANT = ROOT / "examples" / "scenes" / "octant.json"
TINY = np.float32(1.0e-12)
F32 = np.float32


def _shifted(padded: np.ndarray, di: int, dj: int, dk: int) -> np.ndarray:
    """View of an edge-padded array shifted by ``(di, dj, dk)`` nodes (clamped indices)."""
    ni, nj, nk = (s - 2 for s in padded.shape)
    return padded[1 + di : ni + 1 + di, 1 + dj : nj + 1 + dj, 1 + dk : nk + 1 + dk]


def flow_step(
    phi: np.ndarray,
    owner: np.ndarray,
    normals: np.ndarray,
    gauss: np.ndarray,
    *,
    spacing: float,
    dt: float,
    normal_weight: float = 1.0,
    alpha: float = 0.0,
    point_weight: float = 0.0,
) -> np.ndarray:
    """One explicit step of the total-energy flow; returns the new ``phi`` (float32).

    Args:
        phi: Level set, float32, shape ``(ni, nj, nk)``.
        owner: Per-node index into ``normals`` where a constraint owns the node, else any value
            outside ``[0, len(normals))``.
        normals: Constraint normals ``N_i``, shape ``(m, 3)``.
        gauss: Point-attraction field ``G``, same shape as ``phi``.
        spacing: Grid spacing ``h``.
        dt: Time step.
        normal_weight: Weight of the normal term.
        alpha: Weight of the smoothness term.
        point_weight: ``w_P``, rate of the exact decay of the point term.
    """
    phi = np.asarray(phi, dtype=F32)
    h = F32(spacing)
    dt = F32(dt)
    inv_2h = F32(0.5) / h
    inv_h2 = F32(1.0) / (h * h)
    inv_4h2 = F32(0.25) * inv_h2
    p = np.pad(phi, 1, mode="edge")
    c = phi
    xp, xm = _shifted(p, 1, 0, 0), _shifted(p, -1, 0, 0)
    yp, ym = _shifted(p, 0, 1, 0), _shifted(p, 0, -1, 0)
    zp, zm = _shifted(p, 0, 0, 1), _shifted(p, 0, 0, -1)
    px = (xp - xm) * inv_2h
    py = (yp - ym) * inv_2h
    pz = (zp - zm) * inv_2h
    g2 = px * px + py * py + pz * pz
    rate = np.zeros_like(phi)

    if alpha != 0.0:
        two_c = F32(2.0) * c
        pxx = (xp - two_c + xm) * inv_h2
        pyy = (yp - two_c + ym) * inv_h2
        pzz = (zp - two_c + zm) * inv_h2
        del two_c
        pxy = (_shifted(p, 1, 1, 0) - _shifted(p, 1, -1, 0) - _shifted(p, -1, 1, 0)
               + _shifted(p, -1, -1, 0)) * inv_4h2
        pxz = (_shifted(p, 1, 0, 1) - _shifted(p, 1, 0, -1) - _shifted(p, -1, 0, 1)
               + _shifted(p, -1, 0, -1)) * inv_4h2
        pyz = (_shifted(p, 0, 1, 1) - _shifted(p, 0, 1, -1) - _shifted(p, 0, -1, 1)
               + _shifted(p, 0, -1, -1)) * inv_4h2
        xx, yy, zz = px * px, py * py, pz * pz
        num = (pxx * (yy + zz) + pyy * (xx + zz) + pzz * (xx + yy)
               - F32(2.0) * (px * py * pxy + px * pz * pxz + py * pz * pyz))
        del pxx, pyy, pzz, pxy, pxz, pyz, xx, yy, zz
        flat = g2 < TINY
        g = np.sqrt(g2)
        with np.errstate(divide="ignore", invalid="ignore"):
            kappa = np.clip(num / (g2 * g), -F32(1.0) / h, F32(1.0) / h)
        term = kappa * g
        term[flat] = 0.0
        rate += F32(alpha) * term
        del num, kappa, term, flat

    if normal_weight != 0.0:
        normals = np.asarray(normals, dtype=F32).reshape(-1, 3)
        # n - V is zero except where a constraint owns the node: fill those nodes only
        owned = np.nonzero((owner >= 0) & (owner < len(normals)))
        offset = np.zeros((3,) + phi.shape, dtype=F32)
        if owned[0].size:
            gx, gy, gz = px[owned], py[owned], pz[owned]
            length = np.sqrt(gx * gx + gy * gy + gz * gz)
            flat = length < TINY
            safe = np.where(flat, F32(1.0), length)
            n = np.stack([gx / safe, gy / safe, gz / safe])
            n[:, flat] = 0.0
            offset[(slice(None),) + owned] = n - normals[owner[owned]].T
        q = np.pad(offset, ((0, 0), (1, 1), (1, 1), (1, 1)), mode="edge")
        div = ((_shifted(q[0], 1, 0, 0) - _shifted(q[0], -1, 0, 0))
               + (_shifted(q[1], 0, 1, 0) - _shifted(q[1], 0, -1, 0))
               + (_shifted(q[2], 0, 0, 1) - _shifted(q[2], 0, 0, -1))) * inv_2h
        rate += F32(normal_weight) * np.sqrt(g2) * div
        del offset, q, div

    out = c + dt * rate
    if point_weight != 0.0:
        out *= np.exp(-F32(point_weight) * np.asarray(gauss, dtype=F32) * dt)
    return out


def flow_inputs(solver) -> tuple:
    """``(owner, normals, gauss)`` device arrays of a Reconstructor, for the dense kernel."""
    names = ("owner", "normals", "gauss")
    missing = [n for n in names if not hasattr(solver.workspace, n)]
    if missing:
        raise AttributeError(
            f"Reconstructor.workspace no longer holds {', '.join(missing)}: update "
            "benchmarks/numpy_step.py"
        )
    return tuple(getattr(solver.workspace, n) for n in names)


def dense_step(solver, out) -> None:
    """Launch warpspec's dense flow-step kernel on a solver's state into ``out``."""
    from warpspec.kernels.flow import launch_flow_step

    owner, normals, gauss = flow_inputs(solver)
    launch_flow_step(solver.workspace.phi, owner, normals, gauss, out, spacing=solver.grid.spacing,
                     dt=solver.dt, normal_weight=1.0, alpha=solver.alpha,
                     point_weight=solver.w_point)


def _compare(phi, owner, normals, gauss, *, spacing, dt, alpha, point_weight, device) -> dict:
    import warp as wp

    from warpspec.kernels.flow import launch_flow_step

    expect = flow_step(phi, owner, normals, gauss, spacing=spacing, dt=dt, alpha=alpha,
                       point_weight=point_weight)
    arrays = [wp.array(phi, dtype=float, device=device), wp.array(owner, dtype=int, device=device),
              wp.array(normals, dtype=wp.vec3, device=device),
              wp.array(gauss, dtype=float, device=device)]
    out = wp.empty(phi.shape, dtype=float, device=device)
    launch_flow_step(*arrays, out, spacing=spacing, dt=dt, normal_weight=1.0, alpha=alpha,
                     point_weight=point_weight)
    got = out.numpy()
    change = got.astype(np.float64) - phi
    diff = np.abs(got.astype(np.float64) - expect)
    return {
        "shape": phi.shape,
        "owned": int(np.sum((owner >= 0) & (owner < len(normals)))),
        "rel_phi": float(diff.max() / max(np.abs(got).max(), 1e-30)),
        "rel_change": float(diff.max() / max(np.abs(change).max(), 1e-30)),
        "max_change": float(np.abs(change).max()),
    }


def verify(resolution: int = 24, *, device: str = "cpu", seed: int = 0) -> list[dict]:
    """Compare :func:`flow_step` with warpspec's dense ``launch_flow_step`` at a small size.

    Two cases: the octant scene's real state after construction (its rays own a few nodes),
    and a noisy sphere on the same grid where a random tenth of the nodes carry random
    constraint normals (every branch of the stencils, the border included, gets exercised).

    Returns:
        One dict per case: ``rel_phi`` (largest difference over the largest ``|phi|``),
        ``rel_change`` (largest difference over the largest change of ``phi``), and more.
    """
    import warpspec as ws
    from warpspec.kernels.flow import NEIGHBOUR_OWNED, NO_OWNER

    solver = ws.Reconstructor(ws.Scene.load(OCTANT), resolution=resolution,
                              device=device)
    owner, normals, gauss = (a.numpy() for a in flow_inputs(solver))
    phi = solver.phi
    h, dt = solver.grid.spacing, solver.dt
    common = {"spacing": h, "dt": dt, "alpha": solver.alpha, "point_weight": solver.w_point,
              "device": device}
    cases = [dict(case="octant state", **_compare(phi, owner, normals.reshape(-1, 3), gauss,
                                                   **common))]
    rng = np.random.default_rng(seed)
    xs = [np.arange(s) * h for s in phi.shape]
    x, y, z = np.meshgrid(*xs, indexing="ij")
    centre = 0.5 * np.array([xs[0][-1], xs[1][-1], xs[2][-1]]) + 0.3 * h
    radius = 0.3 * min(xs[a][-1] for a in range(3))
    sphere = np.sqrt((x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2) - radius
    noisy = (sphere + 0.2 * h * rng.standard_normal(sphere.shape)).astype(np.float32)
    m = 64
    dirs = rng.standard_normal((m, 3))
    dirs = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32)
    own = rng.integers(0, m, size=phi.shape).astype(np.int32)
    own[rng.random(phi.shape) > 0.1] = NO_OWNER
    own.flat[:5] = -1
    # as the claim kernel leaves it: NO_OWNER only where no six-neighbour is owned
    owned = np.pad((own >= 0) & (own < m), 1)
    beside = np.zeros(phi.shape, dtype=bool)
    for axis in range(3):
        for step in (-1, 1):
            beside |= np.roll(owned, step, axis=axis)[1:-1, 1:-1, 1:-1]
    own[(own == NO_OWNER) & beside] = NEIGHBOUR_OWNED
    cases.append(dict(case="noisy sphere, 10% owned",
                      **_compare(noisy, own, dirs, gauss, **common)))
    return cases


def agreement_table(cases: list[dict]) -> str:
    """Markdown table of :func:`verify`'s results."""
    lines = ["| case | grid | owned nodes | max abs change | max diff / max abs phi "
             "| max diff / max abs change |", "|---|---|---|---|---|---|"]
    for c in cases:
        grid = "x".join(map(str, c["shape"]))
        lines.append(f"| {c['case']} | {grid} | {c['owned']} | {c['max_change']:.3g} "
                     f"| {c['rel_phi']:.2e} | {c['rel_change']:.2e} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=24, help="cells along the octant")
    parser.add_argument("--device", default="cpu", help="Warp device (cpu, cuda:0)")
    parser.add_argument("--tolerance", type=float, default=1e-5,
                        help="largest accepted difference relative to max abs phi")
    args = parser.parse_args(argv)
    cases = verify(args.resolution, device=args.device)
    print(agreement_table(cases))
    worst = max(c["rel_phi"] for c in cases)
    if worst > args.tolerance:
        raise SystemExit(f"NumPy and Warp steps disagree: {worst:.2e} > {args.tolerance:.0e}")
    return cases


if __name__ == "__main__":
    main()
