"""Benchmark of the elastostatic FEM solve: assembly vs scikit-fem, AMG setup, cold/warm CG.

    python benchmarks/mechanics.py --grids 17x17x33,33x33x65,64x64x128 --repeat 3

Each grid runs in its own subprocess (so peak memory is per grid) and the table goes to
benchmarks/results/mechanics.md. Grids are nodes (nz, ny, nx) over the 0.2 x 0.1 x 0.1 m block.
OpenBLAS is limited to one thread: on 2 shared cores its level-1 threads spin and made the CG
dot products and pyamg's setup 3-6x slower (measured while writing this benchmark).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from diathermy.fem.elastic import elastic_assembler  # noqa: E402
from diathermy.fem.geometry import structured_geometry  # noqa: E402
from diathermy.fem.sparsity import build_pattern  # noqa: E402
from diathermy.mesh import Grid, build_tet_mesh  # noqa: E402
from diathermy.physics.mechanics import MechanicsSolver  # noqa: E402
from diathermy.physics.strain_energy import (  # noqa: E402
    relative_strain_energy_error,
    strain_energy_density,
)

E, NU, P0 = 0.27e6, 0.4, 101325.0
RESULTS = Path(__file__).parent / "results" / "mechanics.md"
SKFEM_MAX_NODES = 200_000  # the prototype ran out of memory (> 16 GB) at 64x64x128
DIRECT_MAX_DOFS = 100_000


def peak_gb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


def timed(fn, repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def pressure_field(mesh, rng, scale: float = 1.0) -> np.ndarray:
    """A hot spot under the electrode (~400 kPa excess), perturbed by +-5 % per node."""
    r2 = ((mesh.points - [0.1, 0.05, 0.1]) ** 2).sum(axis=1)
    dp = 4e5 * np.exp(-r2 / 0.01**2) * scale
    return P0 + dp * (1.0 + 0.05 * rng.uniform(-1, 1, mesh.n_nodes))


def skfem_assembly(mesh, repeat: int) -> tuple[float, float, object]:
    """scikit-fem: basis (mappings) and assembly of the same matrix, 1-point quadrature."""
    from skfem import Basis, ElementTetP1, ElementVector, MeshTet, asm
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    sk_mesh = MeshTet(mesh.points.T.copy(), mesh.tets.T.copy())
    t_basis, basis = timed(lambda: Basis(sk_mesh, ElementVector(ElementTetP1()), intorder=1), 1)
    form = linear_elasticity(*lame_parameters(E, NU))
    t_asm, K = timed(lambda: asm(form, basis), repeat)
    dofs = basis.nodal_dofs.T.ravel()  # ours: 3 node + i
    return t_basis, t_asm, K[dofs][:, dofs]


def run_grid(shape: tuple[int, int, int], repeat: int) -> dict:
    out: dict = {"grid": "x".join(map(str, shape))}
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    mesh = build_tet_mesh(Grid(shape))
    out["mesh_s"] = time.perf_counter() - t0
    out["dofs"] = 3 * mesh.n_nodes
    t0 = time.perf_counter()
    pattern = build_pattern(mesh.tets, mesh.n_nodes)
    out["pattern_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    geom = structured_geometry(mesh.points, mesh.tets, mesh.shape_id)
    assembler = elastic_assembler(pattern, geom, mesh.shape_id)
    out["plan_s"] = time.perf_counter() - t0
    Emod = np.full(mesh.n_tets, E)
    out["assembly_s"], K = timed(lambda: assembler.stiffness(Emod, NU), repeat)
    if mesh.n_nodes <= SKFEM_MAX_NODES:
        out["skfem_basis_s"], out["skfem_assembly_s"], K_sk = skfem_assembly(mesh, repeat)
        diff = abs(K.tocsr() - K_sk).max() / abs(K_sk).max()
        out["skfem_max_rel_diff"] = float(diff)
        del K_sk
    del K
    t0 = time.perf_counter()
    solver = MechanicsSolver(mesh, Emod, NU, assembler=assembler)
    out["operator_s"] = time.perf_counter() - t0
    cold, warm = [], []
    for r in range(repeat):
        p = pressure_field(mesh, rng)
        res = solver.solve(p, x0=np.zeros((mesh.n_nodes, 3)))
        if r == 0:
            out["amg_setup_s"] = res.stats.amg_setup_s
            out["levels"] = solver._krylov.hierarchy_levels
        cold.append((res.stats.iterations, res.stats.solve_s))
        # next "time step": every node's pressure moves by up to 5 %, warm start from res.u
        res2 = solver.solve(p * (1 + 0.05 * rng.uniform(-1, 1, mesh.n_nodes)) - 0.0)
        warm.append((res2.stats.iterations, res2.stats.solve_s))
    out["cold_its"], out["cold_s"] = np.median(np.array(cold), axis=0).tolist()
    out["warm_its"], out["warm_s"] = np.median(np.array(warm), axis=0).tolist()
    out["load_s"] = res2.stats.load_s
    if out["dofs"] <= DIRECT_MAX_DOFS:
        import scipy.sparse.linalg as spla

        f = solver.load(p, P0)
        t0 = time.perf_counter()
        spla.spsolve(solver.K.tocsc(), f)
        out["direct_s"] = time.perf_counter() - t0
    if out["dofs"] <= 300_000:  # accuracy of looser tolerances, against rtol 1e-10
        p = pressure_field(mesh, rng)
        ref = MechanicsSolver(mesh, Emod, NU, assembler=assembler, rtol=1e-10).solve(p)
        W_ref = strain_energy_density(geom.grads, mesh.tets, ref.u, E, NU)
        rows = []
        for rtol in (1e-4, 1e-5, 1e-6, 1e-8):
            s = MechanicsSolver(mesh, Emod, NU, assembler=assembler, rtol=rtol)
            res = s.solve(p)
            W = strain_energy_density(geom.grads, mesh.tets, res.u, E, NU)
            err = relative_strain_energy_error(W, W_ref)
            rows.append((rtol, res.stats.iterations, res.stats.solve_s, err))
        out["rtol_table"] = rows
    t0 = time.perf_counter()
    strain_energy_density(geom.grads, mesh.tets, ref.u if "rtol_table" in out else res2.u, E, NU)
    out["strain_energy_s"] = time.perf_counter() - t0
    out["peak_gb"] = peak_gb()
    return out


def fmt(x: float | None, digits: int = 2) -> str:
    return "—" if x is None else f"{x:.{digits}f}"


def write_table(rows: list[dict], repeat: int) -> str:
    lines = [
        "# Mechanics benchmark",
        "",
        f"`python benchmarks/mechanics.py --grids {','.join(r['grid'] for r in rows)} "
        f"--repeat {repeat}`; medians of {repeat} repetitions, one process per grid, "
        "OpenBLAS single-threaded, this shared 2-core VM (absolute times are hints; ratios "
        "within one run are the result). E = 0.27 MPa, nu = 0.4, bottom clamped, pore-pressure "
        "hot spot under the electrode; CG rtol 1e-8 on the Jacobi-scaled system.",
        "",
        "| grid (nz x ny x nx) | DOFs | mesh + pattern + plan (once per mesh) | assembly ours | "
        "scikit-fem basis + assembly | speed-up | AMG setup (levels) | CG cold: its / s | "
        "CG warm: its / s | warm / cold | direct (spsolve) / cold CG | peak GB |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        sk = r.get("skfem_assembly_s")
        sk_txt = f"{r['skfem_basis_s']:.2f} + {sk:.2f} s" if sk is not None else "skipped (> 16 GB)"
        speed = f"{(r['skfem_basis_s'] + sk) / r['assembly_s']:.0f}x" if sk is not None else "—"
        direct = (
            f"{r['direct_s']:.2f} s = {r['direct_s'] / r['cold_s']:.1f}x"
            if "direct_s" in r
            else "too large"
        )
        lines.append(
            f"| {r['grid']} | {r['dofs']:,} | {r['mesh_s']:.2f} + {r['pattern_s']:.2f} + "
            f"{r['plan_s']:.2f} s | {r['assembly_s']:.3f} s | {sk_txt} | {speed} | "
            f"{r['amg_setup_s']:.2f} s ({r['levels']}) | {r['cold_its']:.0f} / {r['cold_s']:.2f} | "
            f"{r['warm_its']:.0f} / {r['warm_s']:.2f} | {r['warm_s'] / r['cold_s']:.2f} | "
            f"{direct} | {r['peak_gb']:.2f} |"
        )
    lines += ["", "Checks: " + "; ".join(
        f"{r['grid']}: ours vs scikit-fem max |dK| / max |K| = {r['skfem_max_rel_diff']:.1e}"
        for r in rows if "skfem_max_rel_diff" in r
    ) + ".", ""]  # fmt: skip
    for r in rows:
        if "rtol_table" not in r:
            continue
        lines += [
            f"Tolerance vs accuracy at {r['grid']} (relative strain-energy error against rtol "
            "1e-10, cold start):",
            "",
            "| rtol | CG its | solve s | strain-energy error |",
            "|---|---|---|---|",
        ]
        lines += [f"| {t:.0e} | {i} | {s:.2f} | {e:.1e} |" for t, i, s, e in r["rtol_table"]]
        lines.append("")
    return "\n".join(lines)


def main() -> None:
    from diathermy.runtime import configure_threads

    configure_threads()  # as the CLI and the server run: one BLAS thread
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grids", default="17x17x33,33x33x65,64x64x128")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--single", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.single:
        shape = tuple(int(s) for s in args.single.split("x"))
        print(json.dumps(run_grid(shape, args.repeat)))  # type: ignore[arg-type]
        return
    rows = []
    for grid in args.grids.split(","):
        cmd = [sys.executable, __file__, "--single", grid, "--repeat", str(args.repeat)]
        proc = subprocess.run(cmd, capture_output=True, text=True, check=True)
        rows.append(json.loads(proc.stdout.strip().splitlines()[-1]))
        print(json.dumps(rows[-1]), flush=True)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(write_table(rows, args.repeat))
    print(RESULTS.read_text())


if __name__ == "__main__":
    main()
