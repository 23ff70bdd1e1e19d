"""Electro-thermal solver benchmark: assembly, AMG, potential and heat solves, coupled steps.

    python benchmarks/electrothermal.py --grids 17x17x33,33x33x65,64x64x128 --repeat 3

(with the package installed, ``pip install -e .``) writes benchmarks/results/electrothermal.md. Every timed quantity is the median of --repeat
runs; the alternatives of one row run side by side in the same process, so read ratios
rather than absolute times (the machines are shared and noisy).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import functools
import os
import platform
import resource
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pyamg
import scipy
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from diathermy.fem.edges import edge_stiffness, laplacian_pattern
from diathermy.fem.geometry import structured_geometry
from diathermy.fem.multigrid import (
    SCALAR_AMG_OPTIONS,
    scaled_candidates,
    unit_diagonal,
    v_cycle_preconditioner,
)
from diathermy.fem.scalar import assemble_diffusion, assemble_robin, lumped_mass
from diathermy.fem.sparsity import build_pattern
from diathermy.mesh import Grid, build_tet_mesh
from diathermy.physics.contact_load import contact_weights
from diathermy.physics.driven_potential import DrivenPotential, ElectrodeDrive
from diathermy.physics.electric import PotentialSolver, joule_heat
from diathermy.physics.electrothermal import ElectroThermal
from diathermy.physics.heat_operator import assemble_heat_operator, heat_mesh  # noqa: E402
from diathermy.physics.thermal import HeatStepper

try:  # not a dependency of the package; without it BLAS keeps its default threads
    from threadpoolctl import threadpool_limits
except ImportError:  # pragma: no cover
    threadpool_limits = None

SIGMA, K, RHO_C, H, T0, T_AMB = 0.33, 0.574, 1019.8 * 3441.0, 25.0, 310.15, 298.15
RADIUS, CENTER, STEP_M, DT = 1.17e-3, (0.1, 0.05, 0.1), 12.35e-3 * 0.03, 0.03
RTOL = 1e-8  # the potential's default
J0 = 5.72e4


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def timed(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    """Median wall time in s of ``repeat`` calls, and the last result."""
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def cg(
    A: sp.csr_matrix,
    b: np.ndarray,
    M: Any,
    rtol: float,
    x0: np.ndarray | None = None,
    scale: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """CG with an iteration count; with ``scale`` = d, A is D^-1/2 K D^-1/2 and b, x0, x are K's."""
    its = [0]

    def tick(_: Any) -> None:
        its[0] += 1

    if scale is not None:
        b = scale * b
        x0 = None if x0 is None else x0 / scale
    x, info = spla.cg(A, b, x0=x0, rtol=rtol, atol=0.0, M=M, maxiter=2000, callback=tick)
    if info != 0:
        raise RuntimeError(f"CG did not converge ({info})")
    return (x if scale is None else scale * x), its[0]


def peak_rss_gb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


class Table:
    """Rows of (quantity, unit/notes) x grids."""

    def __init__(self) -> None:
        self.rows: dict[str, dict[str, str]] = {}

    def put(self, grid: str, key: str, value: str) -> None:
        self.rows.setdefault(key, {})[grid] = value


def f(x: float, digits: int = 3) -> str:
    return f"{x:.{digits}g}"


def bench_potential(tab: Table, g: str, ctx: dict, repeat: int, direct: dict) -> None:
    mesh, geom, stiff = ctx["mesh"], ctx["geom"], ctx["stiff"]
    free = np.setdiff1d(np.arange(mesh.n_nodes), mesh.side_nodes("z-"))
    pattern = ctx["lap_free"]
    sigma = np.full(mesh.n_tets, SIGMA)
    t_ours, A7 = timed(lambda: pattern.matrix(stiff, stiff.weights(sigma)), repeat)
    node_pattern = ctx["node_pattern"]
    t_gen, A15 = timed(
        lambda: assemble_diffusion(node_pattern, geom, sigma)[free][:, free].tocsr(), repeat
    )
    A15.sort_indices()
    tab.put(
        g,
        "potential assembly per sigma: edges / node pattern + elimination (s)",
        f"{f(t_ours)} / {f(t_gen)}",
    )
    tab.put(
        g,
        "potential nnz per row: edges / node pattern",
        f"{A7.nnz / A7.shape[0]:.2f} / {A15.nnz / A15.shape[0]:.2f}",
    )
    x = np.random.default_rng(0).normal(size=A7.shape[0])
    t7, _ = timed(lambda: [A7 @ x for _ in range(20)], repeat)
    t15, _ = timed(lambda: [A15 @ x for _ in range(20)], repeat)
    tab.put(
        g,
        "mat-vec 7-point / 15-entry (ms), ratio",
        f"{f(t7 / 20 * 1e3)} / {f(t15 / 20 * 1e3)}, {t15 / t7:.2f}x",
    )

    contact = contact_weights(mesh, CENTER, RADIUS)
    b = (contact.weights / contact.area_m2)[free]
    As, d = unit_diagonal(A7)  # what PotentialSolver solves
    setups = {}
    ours = {"B": scaled_candidates(d), **SCALAR_AMG_OPTIONS}
    for name, A, opts in (
        ("ours", As, ours),
        ("default7", A7, {}),
        ("default15", A15, {}),
    ):
        setups[name] = timed(
            lambda A=A, opts=opts: pyamg.smoothed_aggregation_solver(A, **opts), repeat
        )
    tab.put(
        g,
        "potential AMG setup: ours (Chebyshev, scaled) / pyamg default, 7-pt / default, 15-entry (s)",
        " / ".join(f(setups[k][0]) for k in ("ours", "default7", "default15")),
    )
    rows = []
    for label, A, scale, ml, lean in (
        ("ours, lean V-cycle", As, d, setups["ours"][1], True),
        ("ours, pyamg V-cycle", As, d, setups["ours"][1], False),
        ("default, 7-pt", A7, None, setups["default7"][1], False),
        ("default, 15-entry", A15, None, setups["default15"][1], False),
    ):
        M = v_cycle_preconditioner(ml) if lean else ml.aspreconditioner(cycle="V")
        t, (_, its) = timed(lambda A=A, M=M, scale=scale: cg(A, b, M, RTOL, scale=scale), repeat)
        rows.append(f"{label}: {its} it {f(t)} s")
    tab.put(g, f"potential cold CG solve, rtol {RTOL:g}", "<br>".join(rows))

    # warm start after the electrode moved one step (12.35 mm/s x 0.03 s)
    moved = contact_weights(mesh, (CENTER[0] + STEP_M, CENTER[1], CENTER[2]), RADIUS)
    b2 = (moved.weights / moved.area_m2)[free]
    M = v_cycle_preconditioner(setups["ours"][1])
    V1f, _ = cg(As, b, M, RTOL, scale=d)
    t_warm, (_, its_w) = timed(lambda: cg(As, b2, M, RTOL, x0=V1f, scale=d), repeat)
    t_cold, (_, its_c) = timed(lambda: cg(As, b2, M, RTOL, scale=d), repeat)
    tab.put(
        g,
        "potential after the electrode moved 0.37 mm: warm / cold (lean V-cycle)",
        f"{its_w} it {f(t_warm)} s / {its_c} it {f(t_cold)} s",
    )

    # a cut: sigma drops to the removed-tissue value in a trench beside the electrode
    c = mesh.centroids()
    trench = (np.abs(c[:, 0] - CENTER[0] - 0.005) < 0.002) & (np.abs(c[:, 1] - CENTER[1]) < 0.01)
    sigma_cut = np.where(trench & (c[:, 2] > CENTER[2] - 0.006), 1e-5, SIGMA)
    A_cut = pattern.matrix(stiff, stiff.weights(sigma_cut))
    As_cut, d_cut = unit_diagonal(A_cut)
    t_stale, (_, its_s) = timed(lambda: cg(As_cut, b2, M, RTOL, x0=V1f, scale=d_cut), repeat)
    t_setup, ml_cut = timed(
        lambda: pyamg.smoothed_aggregation_solver(
            As_cut, B=scaled_candidates(d_cut), **SCALAR_AMG_OPTIONS
        ),
        repeat,
    )
    M_cut = v_cycle_preconditioner(ml_cut)
    t_fresh, (_, its_f) = timed(lambda: cg(As_cut, b2, M_cut, RTOL, x0=V1f, scale=d_cut), 1)
    M_raw = v_cycle_preconditioner(pyamg.smoothed_aggregation_solver(A_cut, **SCALAR_AMG_OPTIONS))
    t_raw, (_, its_r) = timed(lambda: cg(A_cut, b2, M_raw, RTOL, x0=V1f), 1)
    tab.put(
        g,
        "potential after a cut (6 mm trench, sigma 1e-5): old hierarchy / new setup + solve "
        "/ new hierarchy without the diagonal scaling",
        f"{its_s} it {f(t_stale)} s / {f(t_setup)} s + {its_f} it {f(t_fresh)} s / "
        f"{its_r} it {f(t_raw)} s",
    )

    # tolerance vs the energy identity: exact for CG from zero (the residual is orthogonal to
    # the iterate), so measure it after a warm start from the previous electrode position
    parts = []
    for rtol in (1e-6, 1e-8, 1e-10):
        Vf, its = cg(As, b2, M, rtol, x0=V1f, scale=d)
        V = np.zeros(mesh.n_nodes)
        V[free] = Vf
        q = joule_heat(mesh.grid, sigma, V)
        P = float(np.dot(b2, Vf))
        parts.append(f"{rtol:g}: {its} it, {abs(np.dot(q, geom.volumes) - P) / P:.1e}")
    tab.put(
        g,
        "warm-started rtol: CG iterations, rel. error of sum_e q_e vol_e vs int j V",
        "<br>".join(parts),
    )

    # direct solve
    tab.put(
        g,
        "potential direct (splu, MMD_AT_PLUS_A): factor + solve (s), L+U memory; CG/direct",
        direct_solve(A7, b, direct, t_warm),
    )
    tab.put(g, "delivered power at j0 (W), current (A)", _power_row(ctx, sigma))


def _power_row(ctx: dict, sigma: np.ndarray) -> str:
    solver = PotentialSolver(ctx["mesh"], ctx["stiff"])
    sol = DrivenPotential(solver).solve(
        sigma, contact_weights(ctx["mesh"], CENTER, RADIUS), ElectrodeDrive()
    )
    return f"{sol.power_w:.2f} W, {sol.current_a:.4f} A"


def direct_solve(A: sp.csr_matrix, b: np.ndarray, direct: dict, t_iter: float) -> str:
    """splu unless the estimate from the previous grid exceeds the limits."""
    n = A.shape[0]
    prev = direct.get("prev")
    if prev is not None:
        n0, t0, mem0 = prev
        est_t, est_gb = t0 * (n / n0) ** 2, mem0 * (n / n0) ** (4 / 3)
        if est_t > direct["max_s"] or est_gb > direct["max_gb"]:
            return f"skipped: estimated {est_t:.0f} s, {est_gb:.1f} GB from the grid before (n^2, n^4/3)"
    t0 = time.perf_counter()
    lu = spla.splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A")
    t_f = time.perf_counter() - t0
    t0 = time.perf_counter()
    lu.solve(b)
    t_s = time.perf_counter() - t0
    mem = (lu.L.nnz + lu.U.nnz) * 12 / 1e9
    direct["prev"] = (n, t_f + t_s, mem)
    return f"{f(t_f)} + {f(t_s)} s, {mem:.2f} GB; {t_iter / (t_f + t_s):.3f}"


def bench_heat(tab: Table, g: str, ctx: dict, repeat: int) -> None:
    mesh, hm = ctx["mesh"], ctx["heat_mesh"]
    robin = hm.robin(H)
    k = np.full(mesh.n_tets, K)
    w = hm.stiffness.weights(k)
    t_op, _ = timed(lambda: assemble_heat_operator(hm, DT, RHO_C, k, robin), repeat)
    t_rc, _ = timed(lambda: assemble_heat_operator(hm, DT, RHO_C, k, robin, k_weights=w), repeat)
    tab.put(g, "heat operator assembly: new k / new rho c only (s)", f"{f(t_op)} / {f(t_rc)}")
    rng = np.random.default_rng(1)
    T = T0 + rng.uniform(0, 20, mesh.n_nodes)
    for dt in (DT, 10.0):
        parts = []
        for pc in ("auto", "jacobi", "amg"):
            stepper = HeatStepper(hm, h_w_per_m2_k=H, t_ambient_k=T_AMB, preconditioner=pc)
            first = stepper.step(T, dt, rho_c=RHO_C, k=K)  # assembly and setup
            t, res = timed(lambda s=stepper, dt=dt: s.step(T, dt, rho_c=RHO_C, k=K), repeat)
            st = res.stats
            label = f"auto->{st.preconditioner}" if pc == "auto" else pc
            setup = first.stats.setup_s + first.stats.assembly_s
            parts.append(f"{label}: {st.iterations} it {f(t)} s (+{f(setup)} s first)")
        op = stepper.operator(dt, RHO_C, K)[0]
        parts.append(f"(r = {op.dominance:.2f}, theta > 1/2 at {op.fallback_nodes.size} nodes)")
        tab.put(g, f"heat step dt {dt:g} s: iterations, time", "<br>".join(parts))


def prototype_step(ctx: dict, T: np.ndarray, contact: Any) -> np.ndarray:
    """The straightforward path: full node-pattern assembly, fresh default AMG, every step."""
    mesh, geom, pattern = ctx["mesh"], ctx["geom"], ctx["node_pattern"]
    free = np.setdiff1d(np.arange(mesh.n_nodes), mesh.side_nodes("z-"))
    sigma = np.full(mesh.n_tets, SIGMA)
    A = assemble_diffusion(pattern, geom, sigma)[free][:, free].tocsr()
    b = J0 * contact.weights[free]
    ml = pyamg.smoothed_aggregation_solver(A)
    Vf, _ = cg(A, b, ml.aspreconditioner(), 1e-8)
    V = np.zeros(mesh.n_nodes)
    V[free] = Vf
    q = joule_heat(mesh.grid, sigma, V)
    Kt = assemble_diffusion(pattern, geom, np.full(mesh.n_tets, K))
    m = lumped_mass(geom, mesh.tets, mesh.n_nodes, RHO_C)
    R = assemble_robin(mesh.points, mesh.surface_triangles(), mesh.n_nodes, H)
    L = (Kt + R) * 0.5
    A_T = (sp.diags(m / DT) + L).tocsr()
    f_q = np.bincount(mesh.tets.ravel(), np.repeat(q * geom.volumes / 4, 4), minlength=mesh.n_nodes)
    rhs = m / DT * T - L @ T + R @ np.full(mesh.n_nodes, T_AMB) + f_q
    ml_T = pyamg.smoothed_aggregation_solver(A_T)
    T_new, _ = cg(A_T, rhs, ml_T.aspreconditioner(), 1e-10, x0=T)
    return T_new


def bench_coupled(tab: Table, g: str, ctx: dict, repeat: int) -> None:
    mesh, geom = ctx["mesh"], ctx["geom"]
    kw = {"sigma": SIGMA, "drive": ElectrodeDrive(), "rho_c": RHO_C, "k": K}
    results = {}
    variants = [
        ("staggered", False, None),
        ("staggered", True, None),
        ("monolithic", False, "auto"),
        ("monolithic", True, "auto"),
        ("monolithic", True, "amg"),
    ]
    for method, moving, block in variants:
        et = ElectroThermal(mesh, geom, stiffness=ctx["stiff"], h_w_per_m2_k=H, t_ambient_k=T_AMB)
        step = et.staggered_step
        if method == "monolithic":
            step = functools.partial(et.monolithic_step, thermal_block=block)
        T = np.full(mesh.n_nodes, T0)
        first = step(T, DT, contact=contact_weights(mesh, CENTER, RADIUS), **kw)
        T, walls, its, passes, parts = first.T, [], [], [], []
        for i in range(repeat):
            x = CENTER[0] + (i + 1) * STEP_M * moving
            res = step(
                T, DT, contact=contact_weights(mesh, (x, CENTER[1], CENTER[2]), RADIUS), **kw
            )
            T = res.T
            walls.append(res.wall_s)
            its.append(res.potential.iterations if res.potential else res.heat.iterations)
            passes.append(res.picard_passes)
            if res.potential is not None:
                p, h = res.potential, res.heat
                pot = p.assembly_s + p.setup_s + p.solve_s
                heat = h.assembly_s + h.setup_s + h.solve_s
                parts.append((pot, heat, res.wall_s - pot - heat))
        results[(method, moving, block)] = wall = statistics.median(walls)
        name = f"{method} step, {'moving' if moving else 'fixed'} electrode"
        if method == "monolithic":
            name += f", T block {block} (s)"
            detail = f"{int(np.median(its))} GMRES it, {int(np.median(passes))} pass(es)"
        else:
            name += " (s)"
            detail = f"{int(np.median(its))} potential CG it"
        tab.put(g, name, f"{f(wall)} ({detail}; first step {f(first.wall_s)})")
        if parts:
            pot, heat, rest = np.median(np.array(parts), axis=0)
            ctx["summary"][(method, moving)] = (wall, pot, heat, rest)
            tab.put(
                g,
                f"{method}, {'moving' if moving else 'fixed'}: potential / heat solve / "
                "rest (Joule heat, rhs, energy) (s)",
                f"{f(pot)} / {f(heat)} / {f(rest)}",
            )
    T = np.full(mesh.n_nodes, T0)
    walls = []
    for i in range(repeat):
        contact = contact_weights(mesh, (CENTER[0] + i * STEP_M, CENTER[1], CENTER[2]), RADIUS)
        t0 = time.perf_counter()
        T = prototype_step(ctx, T, contact)
        walls.append(time.perf_counter() - t0)
    proto = statistics.median(walls)
    ctx["summary"]["prototype"] = proto
    tab.put(
        g,
        "straightforward prototype step (s): node pattern, fresh default AMG, rtol 1e-8",
        f(proto),
    )
    tab.put(
        g,
        "prototype / ours: staggered fixed, staggered moving, monolithic moving",
        ", ".join(
            f"{proto / results[k]:.1f}x"
            for k in (
                ("staggered", False, None),
                ("staggered", True, None),
                ("monolithic", True, "auto"),
            )
        ),
    )


def bench_grid(shape: tuple[int, int, int], repeat: int, tab: Table, direct: dict) -> dict:
    """Fill the grid's column of ``tab``; returns the coupled-step timings for the summary."""
    g = "x".join(map(str, shape))
    log(f"grid {g}: mesh")
    t0 = time.perf_counter()
    mesh = build_tet_mesh(Grid(shape))
    geom = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
    t_mesh = time.perf_counter() - t0
    t0 = time.perf_counter()
    stiff = edge_stiffness(geom, mesh.tets, mesh.n_nodes)
    free = np.setdiff1d(np.arange(mesh.n_nodes), mesh.side_nodes("z-"))
    lap_free = laplacian_pattern(stiff, free)
    hm = heat_mesh(mesh, geom, stiff)
    t_edges = time.perf_counter() - t0
    t0 = time.perf_counter()
    node_pattern = build_pattern(mesh.tets, mesh.n_nodes)
    t_pattern = time.perf_counter() - t0
    tab.put(g, "nodes / tets", f"{mesh.n_nodes:,} / {mesh.n_tets:,}")
    tab.put(
        g,
        "once per mesh: mesh + geometry / edge couplings + CSR patterns / node pattern (s)",
        f"{f(t_mesh)} / {f(t_edges)} / {f(t_pattern)}",
    )
    ctx = {
        "mesh": mesh,
        "geom": geom,
        "stiff": stiff,
        "lap_free": lap_free,
        "heat_mesh": hm,
        "node_pattern": node_pattern,
        "summary": {},
    }
    log(f"grid {g}: potential")
    bench_potential(tab, g, ctx, repeat, direct)
    log(f"grid {g}: heat")
    bench_heat(tab, g, ctx, repeat)
    log(f"grid {g}: coupled")
    bench_coupled(tab, g, ctx, repeat)
    tab.put(g, "peak RSS so far (GB)", f"{peak_rss_gb():.2f}")
    return ctx["summary"]


def summary(g: str, s: dict) -> str:
    """Where the time of one electro-thermal step goes on the largest grid."""
    fixed, moving, proto = s[("staggered", False)], s[("staggered", True)], s["prototype"]
    return (
        f"\n## Summary ({g})\n\n"
        f"One staggered electro-thermal step takes {f(fixed[0])} s with a fixed electrode "
        f"(heat solve {f(fixed[2])} s, the rest {f(fixed[3])} s: Joule heat scaled from the "
        f"cached unit field, right-hand side, energy terms) and {f(moving[0])} s with a moving "
        f"one: potential {f(moving[1])} s, heat solve {f(moving[2])} s, rest {f(moving[3])} s "
        f"(mostly recomputing q = sigma |grad V|^2 and its nodal load). The straightforward "
        f"prototype took {f(proto)} s per step in the same run: {proto / fixed[0]:.0f}x and "
        f"{proto / moving[0]:.1f}x slower.\n"
    )


NOTES = """
## Notes

- Every time is the median of `--repeat` runs; alternatives of one row ran side by side in one
  process. The machine is shared with other jobs (load average in the header): read ratios,
  not absolute times. BLAS runs single-threaded: on 2 busy cores OpenBLAS threads only contend
  (they made the GMRES Gram-Schmidt several times slower in a trial run).
- **Assembly** goes through edge weights (`diathermy.fem.edges`): the Kuhn stiffness couples
  only axis-parallel edges, so the 15-entry node pattern carries ~8 explicit zeros per row.
  Dropping them halves the stored entries and makes per-sigma assembly 15x or more cheaper; the
  mat-vec gain is smaller than the 2x of the entry count (see its row).
- **Potential**: SA AMG with Chebyshev smoothing and no candidate improvement
  (`diathermy.fem.multigrid.SCALAR_AMG_OPTIONS`), built on the unit-diagonal scaling of K with
  the scaled constant as near-nullspace candidate: as fast as unscaled on uniform sigma and
  robust across a cut (row "after a cut": unscaled, the Chebyshev smoother, a polynomial in K,
  needs 79 iterations at 64x64x128). More iterations than pyamg's default but each much cheaper.
  The lean V-cycle (same module) skips pyamg's two residual evaluations per application;
  `KrylovSolver` still uses pyamg's `aspreconditioner`, so the staggered rows do not have that
  gain yet. rtol 1e-8 (of the scaled system) is the default: the rtol row shows the discrete
  energy identity sum_e q_e |T_e| = int j V (required to 1e-6) after a warm start; from a zero
  start CG keeps it exactly at any rtol (the residual is orthogonal to the iterate).
  `PotentialSolver` keeps its hierarchy when sigma changes until the iterations grow 1.5x; the
  benchmark's 6 mm trench appears at once and doubles them (then it rebuilds), while a cut
  advancing at most 0.15 mm per step changes far less per step.
- **Heat**: Jacobi-PCG wherever its iteration bound from the diagonal dominance stays <= 250;
  at dt 0.03 s that is 2-3 iterations with no setup. AMG takes over at dt ~ 1e3 s and beyond.
  With the EOS changing rho c every step, the operator is re-assembled each step (row "heat
  operator assembly": k's edge weights are kept when only rho c changed).
- **Staggered, fixed electrode**: the potential depends only on sigma and the contact, so the
  unit-current field and its Joule heat are reused and scaled by I and I^2; the step is the heat
  solve plus its right-hand side. **Moving electrode**: one warm-started potential solve per
  step and recomputing q dominate.
- **Monolithic** block-GMRES solves V every step: per iteration one V-cycle on each diagonal
  block, the coupling C (two sparse products of 12 entries per tet) twice, and the block
  mat-vecs. When the electrode moved it needs a second linearisation pass. It exists for
  fidelity to the paper and for a future temperature-dependent sigma; use the staggered step.
- **Direct solve**: SuperLU with a symmetric minimum-degree ordering; the last number is
  (warm iterative potential solve) / (factor + solve). At 64x64x128 it is skipped when the
  estimate from the grid before (time ~ n^2, fill ~ n^4/3) exceeds 2 min or 8 GB.
- **Prototype**: the straightforward path re-assembles on the 15-entry pattern, eliminates the
  bottom by slicing, builds fresh default SA hierarchies and solves the potential (rtol 1e-8)
  and the CN heat step by AMG-CG, every step.
"""


def main(argv: list[str] | None = None) -> None:
    from diathermy.runtime import configure_threads

    configure_threads()  # as the CLI and the server run: one BLAS thread
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--grids", default="17x17x33,33x33x65,64x64x128")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "electrothermal.md"))
    ap.add_argument("--direct-max-s", type=float, default=120.0)
    ap.add_argument("--direct-max-gb", type=float, default=8.0)
    ap.add_argument(
        "--blas-threads", type=int, default=1, help="BLAS threads (1: they only contend on 2 cores)"
    )
    args = ap.parse_args(argv)
    grids = [tuple(int(n) for n in s.split("x")) for s in args.grids.split(",")]
    tab = Table()
    direct = {"max_s": args.direct_max_s, "max_gb": args.direct_max_gb}
    load0 = os.getloadavg()
    t_start = time.perf_counter()
    blas = threadpool_limits(args.blas_threads) if threadpool_limits else contextlib.nullcontext()
    with blas:
        for shape in grids:
            last = bench_grid(shape, args.repeat, tab, direct)  # type: ignore[arg-type]
    load1 = os.getloadavg()
    names = ["x".join(map(str, s)) for s in grids]
    lines = [
        "# Electro-thermal solver benchmark",
        "",
        f"`python benchmarks/electrothermal.py --grids {args.grids} --repeat {args.repeat}` "
        f"({datetime.date.today()}, {time.perf_counter() - t_start:.0f} s)",
        "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
        f"load average {load0[0]:.1f} at the start, {load1[0]:.1f} at the end. "
        f"numpy {np.__version__}, scipy {scipy.__version__}, pyamg {pyamg.__version__}, "
        f"BLAS threads {args.blas_threads}. "
        f"Grids are nodes (nz, ny, nx) over the 0.2 x 0.1 x 0.1 m block; dt {DT} s, "
        f"j0 = 5.72e4 A/m^2 on a {RADIUS * 1e3} mm disk, h = {H} on all sides.",
        "",
        "| quantity | " + " | ".join(names) + " |",
        "|---|" + "---|" * len(names),
    ]
    for key, row in tab.rows.items():
        lines.append(f"| {key} | " + " | ".join(row.get(n, "") for n in names) + " |")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n" + summary(names[-1], last) + NOTES)
    log(f"wrote {out}")


if __name__ == "__main__":
    main()
