"""Resolution under the electrode (issue #21): delivered power and electric-solve cost of uniform
grids against graded tensor-product grids, side by side in one run.

    python benchmarks/resolution_prototype.py [--uniform-nz 17 33 49 65] [--fine-mm 1 0.5 ...]

The paper's block (0.2 x 0.1 x 0.1 m, sigma 0.33 S/m), the current-density drive (5.72e4 A/m^2
over a 1.17 mm disk, I = 0.246 A) at the centre of the top face. Uniform grids (nz, nz, 2 nz - 1);
graded grids fine (--fine-mm) over the working box (the contact +- --margin-mm, --margin-mm deep),
growing by --growth up to --max-cell-mm. Each row builds the mesh and solves the potential cold
(AMG setup + CG to rtol 1e-8). References: the equipotential disk I^2/(4 sigma a), the uniform
current density disk 8 I^2/(3 pi^2 sigma a) (what this drive converges to), plus the block's own
resistance by images. Node counts of the moving electrode's working box (path bounding box +
margin) are tabulated beside them (no solve). Writes benchmarks/results/resolution_prototype.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "server")]

from diathermy.engine.electrodes import path_polyline  # noqa: E402
from diathermy.fem.edges import edge_stiffness  # noqa: E402
from diathermy.fem.geometry import structured_geometry  # noqa: E402
from diathermy.mesh import Grid, build_tet_mesh  # noqa: E402
from diathermy.physics.contact_load import contact_weights  # noqa: E402
from diathermy.physics.contact_resistance import (  # noqa: E402
    block_image_resistance,
    equipotential_disk_resistance,
    uniform_flux_disk_resistance,
)
from diathermy.physics.driven_potential import DrivenPotential, ElectrodeDrive  # noqa: E402
from diathermy.physics.electric import PotentialSolver  # noqa: E402
from diathermy.runtime import configure_threads  # noqa: E402
from diathermy.scene.builtin import MOVING_PATH_M  # noqa: E402
from diathermy.scene.models import ElectrodePath  # noqa: E402

BLOCK = (0.2, 0.1, 0.1)
SIGMA, RADIUS, J0 = 0.33, 1.17e-3, 5.72e4
CENTRE = (0.1, 0.05, 0.1)
BYTES_PER_NODE = 16036  # engine, all default effects (benchmarks/results/engine_memory.md fit)
BASE_BYTES = 9.2 * 2**20


def fixed_box(margin: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The fixed electrode's working box: the contact +- margin, margin deep."""
    lo = (CENTRE[0] - margin, CENTRE[1] - margin, BLOCK[2] - margin)
    hi = (CENTRE[0] + margin, CENTRE[1] + margin, BLOCK[2])
    return lo, hi


def moving_box(margin: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The moving electrode's working box: the path's bounding box + margin, margin deep."""
    path = ElectrodePath(waypoints_m=MOVING_PATH_M, speed_m_per_s=12.35e-3, kind="spline")
    poly = path_polyline(path)
    lo, hi = poly.min(axis=0) - margin, poly.max(axis=0) + margin
    return (lo[0], lo[1], BLOCK[2] - margin), (hi[0], hi[1], BLOCK[2])


def solve_power(grid: Grid) -> dict[str, float]:
    """Build the mesh, solve the driven potential cold; power, cost and size of one grid."""
    t0 = time.perf_counter()
    mesh = build_tet_mesh(grid)
    geom = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
    solver = PotentialSolver(mesh, edge_stiffness(geom, mesh.tets, mesh.n_nodes))
    contact = contact_weights(mesh, CENTRE, RADIUS)
    t1 = time.perf_counter()
    sol = DrivenPotential(solver).solve(SIGMA, contact, ElectrodeDrive())
    t2 = time.perf_counter()
    st = sol.stats
    return {
        "nodes": grid.n_nodes,
        "tets": mesh.n_tets,
        "h_mm": 1e3 * min(grid.min_spacing_m),
        "current_a": sol.current_a,
        "power_w": sol.power_w,
        "mesh_s": t1 - t0,
        "solve_s": t2 - t1,
        "amg_setup_s": st.setup_s,
        "cg_s": st.solve_s,
        "iterations": st.iterations,
    }


def graded(fine_mm: float, box, args) -> Grid:  # noqa: ANN001
    return Grid.graded(
        *box, fine_mm * 1e-3, growth=args.growth, max_cell_m=args.max_cell_mm * 1e-3, size_m=BLOCK
    )


def main(argv: list[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--uniform-nz", type=int, nargs="*", default=[17, 33, 49, 65])
    ap.add_argument("--fine-mm", type=float, nargs="*", default=[1.0, 0.5, 0.35, 0.25, 0.125])
    ap.add_argument("--margin-mm", type=float, default=3.0)
    ap.add_argument("--growth", type=float, default=1.25)
    ap.add_argument("--max-cell-mm", type=float, default=6.25)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks/results/resolution_prototype.md")
    args = ap.parse_args(argv)
    configure_threads()
    current = J0 * np.pi * RADIUS**2
    r_block = block_image_resistance(SIGMA, BLOCK, (0.0, 0.0, 0.0), CENTRE[:2])
    p_eq = current**2 * equipotential_disk_resistance(SIGMA, RADIUS)
    p_flux = current**2 * uniform_flux_disk_resistance(SIGMA, RADIUS)
    p_ref = p_flux + current**2 * r_block
    rows = []
    for nz in args.uniform_nz:
        g = Grid((nz, nz, 2 * nz - 1), size_m=BLOCK)
        rows.append({"grid": f"uniform {nz}x{nz}x{2 * nz - 1}", **solve_power(g)})
        print(rows[-1], flush=True)
    box = fixed_box(args.margin_mm * 1e-3)
    for fine in args.fine_mm:
        g = graded(fine, box, args)
        shape = "x".join(str(n) for n in g.shape)
        rows.append({"grid": f"graded {fine:g} mm ({shape})", **solve_power(g)})
        print(rows[-1], flush=True)
    counts = []
    for fine in args.fine_mm:
        gf, gm = graded(fine, box, args), graded(fine, moving_box(args.margin_mm * 1e-3), args)
        counts.append((fine, gf.shape, gf.n_nodes, gm.shape, gm.n_nodes))
    write_report(args, rows, counts, current, (p_eq, p_flux, p_ref, r_block))
    return args.out


def convergence_lines(rows: list[dict], p_ref: float) -> list[str]:
    """Observed order of P over graded rows whose finest cells halve, and the extrapolated limit."""
    graded = sorted((r for r in rows if r["grid"].startswith("graded")), key=lambda r: -r["h_mm"])
    chain = [graded[0]] if graded else []
    for r in graded[1:]:
        if abs(chain[-1]["h_mm"] / r["h_mm"] - 2.0) < 1e-6:
            chain.append(r)
    if len(chain) < 3:
        return []
    p = [r["power_w"] for r in chain]
    orders = [np.log2((p[i] - p[i - 1]) / (p[i + 1] - p[i])) for i in range(1, len(p) - 1)]
    limit = p[-1] + (p[-1] - p[-2]) / (2.0 ** orders[-1] - 1.0)
    hs = " / ".join(f"{r['h_mm']:g}" for r in chain)
    return [
        "",
        f"Graded cells halving ({hs} mm): observed order of P "
        + ", ".join(f"{o:.2f}" for o in orders)
        + f"; Richardson limit {limit:.2f} W = {limit / p_ref:.3f} x the reference.",
    ]


def write_report(args, rows, counts, current, refs) -> None:  # noqa: ANN001
    p_eq, p_flux, p_ref, r_block = refs
    base = next((r for r in rows if r["grid"].startswith("uniform 33x")), rows[0])
    cmd = (
        f"python benchmarks/resolution_prototype.py --uniform-nz "
        f"{' '.join(map(str, args.uniform_nz))} --fine-mm {' '.join(f'{f:g}' for f in args.fine_mm)}"
        f" --margin-mm {args.margin_mm:g} --growth {args.growth:g} --max-cell-mm {args.max_cell_mm:g}"
    )
    lines = [
        "# Resolution under the electrode: uniform vs graded grids (issue #21 prototype)",
        "",
        f"`{cmd}` (shared 2-core machine: read the ratios).",
        "",
        f"Current-density drive: j = {J0:g} A/m^2 over a {RADIUS * 1e3:g} mm disk, "
        f"I = {current:.4f} A, sigma = {SIGMA} S/m, block {BLOCK} m, contact at {CENTRE}. "
        "References: equipotential disk I^2/(4 sigma a) = "
        f"{p_eq:.2f} W; uniform current density disk 8 I^2/(3 pi^2 sigma a) = {p_flux:.2f} W "
        f"(the limit of this drive); the block's own resistance by images {r_block:.2f} ohm "
        f"(+{current**2 * r_block:.2f} W): **reference {p_ref:.2f} W**.",
        "",
        f"Graded grids: fine cells over the contact +- {args.margin_mm:g} mm, "
        f"{args.margin_mm:g} mm deep, growth {args.growth:g} per cell, cells at most "
        f"{args.max_cell_mm:g} mm. Time: mesh + geometry + edge stiffness + contact (mesh), "
        "cold potential solve (AMG setup + CG to rtol 1e-8). Memory: the engine's fit "
        f"{BASE_BYTES / 2**20:.1f} MiB + {BYTES_PER_NODE} B/node (all default effects).",
        "",
        "| grid | nodes | nodes / 33x33x65 | finest cell mm | P W | P / reference | mesh s "
        "| solve s | AMG setup s | CG s | CG its | est. engine MiB |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        mib = (BASE_BYTES + BYTES_PER_NODE * r["nodes"]) / 2**20
        lines.append(
            f"| {r['grid']} | {r['nodes']} | {r['nodes'] / base['nodes']:.2f} | {r['h_mm']:.3g} "
            f"| {r['power_w']:.2f} | {r['power_w'] / p_ref:.3f} | {r['mesh_s']:.2f} "
            f"| {r['solve_s']:.2f} | {r['amg_setup_s']:.2f} | {r['cg_s']:.2f} "
            f"| {r['iterations']} | {mib:.0f} |"
        )
    lines += convergence_lines(rows, p_ref)
    lines += [
        "",
        "Node counts of graded grids (same growth and cap) over the two working regions: the fixed"
        f" electrode's box above, and the moving electrode's path bounding box + {args.margin_mm:g}"
        " mm (the paper's curvilinear path, 12 s at 12.35 mm/s).",
        "",
        "| fine mm | fixed: shape | fixed: nodes | moving path: shape | moving path: nodes "
        "| moving / 33x33x65 |",
        "|---:|---|---:|---|---:|---:|",
    ]
    for fine, sf, nf, sm, nm in counts:
        lines.append(
            f"| {fine:g} | {'x'.join(map(str, sf))} | {nf} | {'x'.join(map(str, sm))} | {nm} "
            f"| {nm / 70785:.1f} |"
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
