"""The networks on the GPU against the CPU (issue #22, item 5): inference and a whole step.

    python benchmarks/gpu.py [--grids default 33x33x65 64x64x128] [--step-grids ...]
                             [--modes full incremental hybrid auto] [--repeat 20] [--steps 6]
                             [--warmup-steps 80] [--warmup-s 120] [--out benchmarks/results/gpu.md]

Run it on a machine with CUDA (the device tool's, when one is lent): every measurement runs on
the CPU and, where ``torch.cuda.is_available()``, on the GPU, in the same run. Without CUDA it
measures the CPU alone and says so.

**Inference**, batch 1, per grid (``default``: the default scene's graded grid, 35x32x48 nodes;
``NZxNYxNX``: a uniform grid of that many nodes): the paper-style network
(``DisplacementCNN``, the shipped model's configuration) and the incremental one
(``IncrementalCNN``, the configuration of benchmarks/results/incremental_network.md). Their cost
does not depend on the weights, so both run with seeded random weights. Per device
(``cpu 1t``: one torch thread, as the engine's server runs; ``cpu Nt``: every core;
``cuda``: float32, PyTorch's defaults, TF32 convolutions included; ``cuda bf16``: under
autocast): the median and p90 over ``--repeat`` calls after three warm-ups of the network's
forward pass alone (synchronised) and of the whole call the engine makes (numpy fields in,
numpy displacement out: encoding, host-to-device and back).

**A whole step**, per grid (the ``default`` scene, 50 W, on that grid, stepped with
the engine's defaults to two steps after its first cut, or ``--warmup-steps``, and
checkpointed): from the checkpoint, in lockstep, ``full`` (every effect solved in full: the
reference), ``incremental`` (the default: persistence, Ritz-scaled, patch-corrected, guarded),
``hybrid`` (``mechanics.backend: cnn``, the paper's method: the network's displacement every
step, Ritz-scaled, the patch) and ``auto`` (the incremental mode asking the network where
persistence has nothing). The network is the shipped model where the grid has one, else a
checkpoint of the shipped configuration with seeded random weights (its time is right; the
patch it needs is not a trained model's: the report says which). Each device runs in a child
process of its own (``CUDA_VISIBLE_DEVICES`` empty for the CPU), the two at once. Per mode:
the median step and mechanics wall time and the max strain-energy error against ``full``. The
default graded grid has no whole hybrid step: the engine refuses the CNN on graded grids
(``mechanics.model``: the surrogates are trained on uniform grids), so there the inference
stands beside the steps it would join, ``full`` and ``incremental``.

Writes ``--out`` (markdown) and the same name with .json.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
sys.path.insert(0, str(ROOT / "server"))
sys.path.insert(0, str(ROOT / "benchmarks"))

STEP_MODES: dict[str, dict[str, Any]] = {
    "full": {"incremental": False},
    "incremental": {},
    "hybrid": {"backend": "cnn"},
    "auto": {"predictor": "auto"},
}
INCREMENTAL_WIDTH = 12  # the configuration of benchmarks/results/incremental_network.md


def parse_grid(text: str) -> tuple[int, int, int] | None:
    """'default' -> None (the default scene's own grid); 'NZxNYxNX' -> its node counts."""
    if text == "default":
        return None
    parts = text.lower().split("x")
    if len(parts) != 3 or not all(p.isdigit() and int(p) >= 3 for p in parts):
        raise argparse.ArgumentTypeError(f"grid {text!r}: 'default' or NZxNYxNX, each >= 3")
    return (int(parts[0]), int(parts[1]), int(parts[2]))


def grid_shape(grid: tuple[int, int, int] | None) -> tuple[int, int, int]:
    from diathermy.scene import builtin_scene

    return tuple(builtin_scene("default").node_shape) if grid is None else grid  # type: ignore[return-value]


def label(grid: tuple[int, int, int] | None) -> str:
    shape = "x".join(map(str, grid_shape(grid)))
    return f"{shape} graded (default)" if grid is None else f"{shape} uniform"


def cores() -> int:
    """The CPUs this process may run on (its affinity, e.g. under taskset)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def devices() -> list[str]:
    import torch

    out = ["cpu 1t", f"cpu {cores()}t"] if cores() > 1 else ["cpu 1t"]
    if torch.cuda.is_available():
        out += ["cuda", "cuda bf16"]
    return out


def timed(fn: Callable[[], Any], repeat: int, sync: Callable[[], None]) -> dict[str, float]:
    """Median and p90 seconds of ``fn`` over ``repeat`` calls after warm-ups (three, one for a
    call over 0.1 s); a slow call is repeated only to about 2 s in all (at least 3 times)."""
    t0 = time.perf_counter()
    fn()
    sync()
    first = time.perf_counter() - t0
    for _ in range(2 if first < 0.1 else 0):
        fn()
    sync()
    times = []
    for _ in range(min(repeat, max(3, int(2.0 / max(first, 1e-6))))):
        t0 = time.perf_counter()
        fn()
        sync()
        times.append(time.perf_counter() - t0)
    times.sort()
    p90 = times[max(0, math.ceil(0.9 * len(times)) - 1)]  # nearest rank
    return {"median_s": statistics.median(times), "p90_s": p90}


def shipped_config() -> dict[str, Any]:
    """The shipped model's constructor arguments (its architecture)."""
    from diathermy.surrogates.backend import default_model_path
    from diathermy.surrogates.checkpoint import load_checkpoint

    return load_checkpoint(default_model_path((33, 33, 65))).model.constructor_args()


def inference(grids: list[tuple[int, int, int] | None], repeat: int) -> list[dict[str, Any]]:
    """Every network on every grid and device: forward alone and the engine's whole call."""
    import numpy as np

    rows = []
    cfg = shipped_config()
    for grid in grids:
        shape = grid_shape(grid)
        rng = np.random.default_rng(0)
        p = (101325.0 + 2e6 * rng.random(shape)).astype(np.float32)
        fields = {
            "p": p,
            "p_prev": (p - 1e4).astype(np.float32),
            "phi": (1e-3 * rng.standard_normal(shape)).astype(np.float32),
            "u_prev": (1e-4 * rng.standard_normal((3, *shape))).astype(np.float32),
        }
        for dev in devices():
            for row in on_device(dev, cfg, fields, repeat):
                row["grid"] = label(grid)
                rows.append(row)
                print(f"  {row['grid']} {row['model']} {dev}: forward "
                      f"{row['forward_median_s'] * 1e3:.2f} ms, call "
                      f"{row['call_median_s'] * 1e3:.2f} ms", flush=True)  # fmt: skip
    return rows


def on_device(
    dev: str, cfg: dict[str, Any], fields: dict[str, Any], repeat: int
) -> list[dict[str, Any]]:
    """Both networks on ``dev`` ('cpu Nt', 'cuda', 'cuda bf16') for one grid's ``fields``."""
    import torch

    from diathermy.surrogates.cnn import DisplacementCNN
    from diathermy.surrogates.incremental import IncrementalCNN, IncrementalConfig
    from diathermy.surrogates.inference import predict

    torch.manual_seed(0)
    device = torch.device("cuda" if dev.startswith("cuda") else "cpu")
    threads = torch.get_num_threads()
    torch.set_num_threads(int(dev.split()[1][:-1]) if dev.startswith("cpu") else 1)
    bf16 = dev.endswith("bf16")
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    shape = fields["p"].shape
    direct = DisplacementCNN.from_constructor_args(cfg).eval().to(device)
    inc = IncrementalCNN(IncrementalConfig(width=INCREMENTAL_WIDTH)).eval().to(device)
    torch.nn.init.normal_(inc.out.weight, std=0.1)  # not the zero start: a real output
    xd = torch.randn(1, 2, *shape, device=device)
    xi = torch.randn(1, 7, *shape, device=device)
    host = {k: torch.from_numpy(v[None]) for k, v in fields.items()}

    def ctx() -> Any:
        if bf16:
            return torch.autocast("cuda", dtype=torch.bfloat16)
        return contextlib.nullcontext()

    def forward_direct() -> Any:
        with torch.inference_mode(), ctx():
            return direct(xd)

    def forward_inc() -> Any:
        with torch.inference_mode(), ctx():
            return inc(xi)

    def call_direct() -> Any:
        with ctx():
            return predict(direct, fields["p"], fields["phi"])

    def call_inc() -> Any:
        with torch.inference_mode(), ctx():
            a = [host[k].to(device) for k in ("p", "p_prev", "u_prev", "phi")]
            u = inc.predict_displacement(*a)
            return u.permute(0, 2, 3, 4, 1).float().cpu().numpy()

    rows = []
    for name, f_fwd, f_call in (
        ("direct (paper)", forward_direct, call_direct),
        ("incremental", forward_inc, call_inc),
    ):
        row: dict[str, Any] = {"model": name, "device": dev}
        for part, fn in (("forward", f_fwd), ("call", f_call)):
            t = timed(fn, repeat, sync)
            row[f"{part}_median_s"], row[f"{part}_p90_s"] = t["median_s"], t["p90_s"]
        if device.type == "cuda":
            row["peak_gpu_mb"] = torch.cuda.max_memory_allocated() / 2**20
            torch.cuda.reset_peak_memory_stats()
        rows.append(row)
    torch.set_num_threads(threads)
    return rows


def random_model(shape: tuple[int, int, int], spacing: tuple[float, ...], path: Path) -> Path:
    """A checkpoint of the shipped configuration with seeded random weights for ``shape``."""
    import torch

    from diathermy.surrogates.checkpoint import save_checkpoint
    from diathermy.surrogates.cnn import DisplacementCNN

    torch.manual_seed(0)
    model = DisplacementCNN.from_constructor_args(shipped_config())
    save_checkpoint(path, model, grid_shape=shape, spacing_m=spacing)  # type: ignore[arg-type]
    return path


def step_scene(grid: tuple[int, int, int] | None) -> Any:
    """The default scene (50 W, fixed electrode) on its own grid or a uniform one."""
    from diathermy.scene import builtin_scene

    scene = builtin_scene("default")
    return scene if grid is None else scene.on_uniform_grid(grid)


def warm(
    grid: tuple[int, int, int] | None, work: Path, warmup: int, warmup_s: float
) -> dict[str, Any]:
    """The grid's scene stepped with the engine's defaults to two steps after its first cut (at
    most ``warmup`` steps, or ``warmup_s`` seconds once the mechanics has run), checkpointed;
    the model the hybrid modes use (shipped or random) beside it."""
    from diathermy.engine.simulation import Simulation
    from diathermy.errors import SceneError
    from diathermy.surrogates.backend import default_model_path

    scene = step_scene(grid)
    tag = "default" if grid is None else "x".join(map(str, grid))
    t0 = time.perf_counter()
    sim = Simulation(scene)
    first_cut: int | None = None
    mechanics = False
    while sim.step_index < warmup:
        r = sim.step()
        mechanics = mechanics or r.ran("mechanics")
        if first_cut is None and r.cut_volume_m3 > 0:
            first_cut = sim.step_index
        if first_cut is not None and sim.step_index >= first_cut + 2:
            break
        if mechanics and time.perf_counter() - t0 > warmup_s:
            break
    path = work / f"{tag}.h5"
    sim.save_checkpoint(path)
    steps_done, spacing = sim.step_index, sim.disc.grid.min_spacing_m  # uniform: the spacing
    del sim
    info: dict[str, Any] = {
        "grid": label(grid), "scene": scene.name, "checkpoint": str(path),
        "first_cut_step": first_cut, "warmup_s": time.perf_counter() - t0,
        "warmup_steps": steps_done, "mechanics_ran": mechanics,
        "nodes": int(scene.node_shape[0] * scene.node_shape[1] * scene.node_shape[2]),
    }  # fmt: skip
    if grid is not None:
        try:
            info["model"], info["model_kind"] = str(default_model_path(grid)), "shipped"
        except SceneError:  # no shipped model for this grid
            info["model"] = str(random_model(grid, spacing, work / f"random_{tag}.pt"))
            info["model_kind"] = "random weights"
    return info


def run_steps(info: dict[str, Any], steps: int) -> dict[str, Any]:
    """Child: the modes that apply from the checkpoint in lockstep on this process's device: on
    the CPU all of them; on the GPU only those with a network (the others run no torch)."""
    import numpy as np
    import torch
    from realtime import load_as

    from diathermy.physics.strain_energy import relative_strain_energy_error

    chosen = info.get("modes", list(STEP_MODES))
    networks = [m for m in ("hybrid", "auto") if m in chosen and "model" in info]
    plain = [m for m in ("full", "incremental") if m in chosen]
    modes = networks if torch.cuda.is_available() else [*plain, *networks]
    if not modes:
        return {"device": "cuda", "gpu": torch.cuda.get_device_name(), "modes": {}}
    sims = {}
    for m in modes:
        extra = {"model": info["model"]} if m in ("hybrid", "auto") else {}
        sims[m] = load_as(Path(info["checkpoint"]), **STEP_MODES[m], **extra)
    rec: dict[str, dict[str, list[float]]] = {m: {"step": [], "mech": [], "se": []} for m in modes}
    for _ in range(steps):
        for m, sim in sims.items():
            r = sim.step()
            mech = r.effects.get("mechanics")
            rec[m]["step"].append(r.wall_s)
            rec[m]["mech"].append(mech.wall_s if mech is not None and mech.ran else 0.0)
        W_ref = sims["full"].state["strain_energy"] if "full" in sims else None
        for m, sim in sims.items():
            W = sim.state["strain_energy"]
            ok = W_ref is not None and W is not None and bool(np.any(W_ref))
            rec[m]["se"].append(relative_strain_energy_error(W, W_ref) if ok else float("nan"))
    out = {
        "device": "cuda" if torch.cuda.is_available() else "cpu",
        "gpu": torch.cuda.get_device_name() if torch.cuda.is_available() else None,
        "modes": {},
    }
    for m, r in rec.items():
        out["modes"][m] = {
            "median_step_s": statistics.median(r["step"]),
            "median_mech_s": statistics.median(r["mech"]),
            "max_se_error": float(np.max(r["se"])),
            "steps": len(r["step"]),
        }
    return out


def whole_steps(
    grids: list[tuple[int, int, int] | None],
    modes: list[str],
    steps: int,
    warmup: int,
    warmup_s: float,
    work: Path,
    done: Callable[[list[dict[str, Any]]], None],
) -> list[dict[str, Any]]:
    """Per grid: the warm-up here, then one child per device from its checkpoint, at once;
    ``done`` is handed the grids measured so far after each."""
    import torch

    out: list[dict[str, Any]] = []
    for grid in grids:
        info = warm(grid, work, warmup, warmup_s)
        info["modes"] = modes
        print(f"  {info['grid']}: warmed up in {info['warmup_s']:.0f} s", flush=True)
        cuda = torch.cuda.is_available()
        children = {}
        for dev in ["cpu"] + (["cuda"] if cuda else []):
            env = dict(os.environ)
            if dev == "cpu":
                env["CUDA_VISIBLE_DEVICES"] = ""
            cmd = [sys.executable, __file__, "_steps", json.dumps(info), str(steps)]
            children[dev] = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, text=True)
        info["devices"] = {}
        for dev, proc in children.items():
            stdout, _ = proc.communicate()
            lines = [ln for ln in stdout.splitlines() if ln.startswith("{")]
            info["devices"][dev] = json.loads(lines[-1]) if proc.returncode == 0 and lines else {
                "error": f"child exited {proc.returncode}"}  # fmt: skip
        out.append(info)
        done(out)
    return out


def ms(s: float) -> str:
    return f"{1e3 * s:.2f}" if s < 1 else f"{1e3 * s:.0f}"


def write(out: Path, meta: dict[str, Any], inf: list[dict], st: list[dict]) -> None:
    lines = [
        "# Networks on the GPU against the CPU (issue #22, item 5)",
        "",
        f"`{meta['command']}` on {meta['machine']}; torch {meta['torch']}, "
        f"{meta['gpu'] or 'no GPU (CUDA not available: CPU rows only)'}; started "
        f"{meta['started']}, {meta['minutes']:.1f} min in all.",
        "",
        "## Inference, batch 1 (ms; median, p90 in brackets)",
        "",
        "*forward*: the network alone (synchronised); *call*: what the engine pays per "
        "prediction, numpy fields in and numpy displacement out (encoding, copies to the device "
        "and back). Random weights: the cost does not depend on them.",
        "",
        "| grid | network | device | forward | call | x cpu 1t (call) | GPU MB |",
        "|---|---|---|---:|---:|---:|---:|",
    ]
    base = {(r["grid"], r["model"]): r["call_median_s"] for r in inf if r["device"] == "cpu 1t"}
    for r in inf:
        ratio = base[(r["grid"], r["model"])] / r["call_median_s"]
        lines.append(
            f"| {r['grid']} | {r['model']} | {r['device']} | {ms(r['forward_median_s'])} "
            f"({ms(r['forward_p90_s'])}) | {ms(r['call_median_s'])} ({ms(r['call_p90_s'])}) | "
            f"{ratio:.1f}x | {r.get('peak_gpu_mb', 0):.0f} |"
        )
    lines += [
        "",
        "## A whole step from two steps after the first cut (s; median over the steps)",
        "",
        "`full`: every effect in full (the reference); `incremental`: the default, persistence; "
        "`hybrid`: `mechanics.backend: cnn` (the network every step, Ritz scale, patch); "
        "`auto`: persistence, the network where persistence has nothing. Max SE: the largest "
        "relative strain-energy error against `full` at the same step, in the same process (the "
        "CPU's: the GPU's child runs only the modes with a network; `full` and `incremental` "
        "run no torch, so their time is the same on either).",
        "",
        "| grid | scene | model | device | mode | steps | step s | mechanics s | max SE error |",
        "|---|---|---|---|---|---:|---:|---:|---:|",
    ]
    for info in st:
        for dev, res in info.get("devices", {}).items():
            if "error" in res:
                lines.append(f"| {info['grid']} | {info['scene']} | | {dev} | {res['error']} |"
                             " | | | |")  # fmt: skip
                continue
            for m, r in res["modes"].items():
                model = info.get("model_kind", "none") if m in ("hybrid", "auto") else "-"
                e = r["max_se_error"]
                se = "-" if e != e else f"{100 * e:.3g} %"  # NaN: no full run beside it
                lines.append(
                    f"| {info['grid']} | {info['scene']} | {model} | {dev} | {m} | {r['steps']} "
                    f"| {r['median_step_s']:.3f} | {r['median_mech_s']:.3f} | "
                    f"{se} |"
                )
    lines += [
        "",
        "Warm-ups (the engine's defaults): "
        + "; ".join(
            f"{i['grid']} {i['scene']}, {i['warmup_steps']} steps in {i['warmup_s']:.0f} s, "
            f"first cut at step {i['first_cut_step']}"
            + ("" if i["mechanics_ran"] else " (the mechanics never ran: nothing to compare)")
            for i in st
        )
        + ".",
    ]
    if any(i["grid"].endswith("(default)") for i in st):
        lines += [
            "",
            "The default grid is graded: the engine runs no CNN there (`mechanics.backend: cnn` "
            "and `predictor: auto` need a uniform grid), so its rows show the steps a network "
            "would join; add the inference above to see what it would cost.",
        ]
    notes = out.with_name(out.stem + "_notes.md")
    if notes.exists():
        lines += ["", notes.read_text().rstrip()]
    out.write_text("\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["_steps"]:
        from diathermy.runtime import configure_threads

        configure_threads()
        print(json.dumps(run_steps(json.loads(argv[1]), int(argv[2]))), flush=True)
        return 0
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--grids", nargs="+", type=parse_grid,
                    default=[None, (33, 33, 65), (64, 64, 128)])  # fmt: skip
    ap.add_argument("--step-grids", nargs="*", type=parse_grid, default=None,
                    help="grids of the whole-step part (default: --grids; none: skip it)")  # fmt: skip
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--steps", type=int, default=6, help="lockstep steps per mode")
    ap.add_argument("--modes", nargs="+", choices=list(STEP_MODES), default=list(STEP_MODES),
                    help="the whole-step modes (without full: no errors, a cheaper run on "
                    "large grids)")  # fmt: skip
    ap.add_argument("--warmup-steps", type=int, default=80, help="cap of the warm-up")
    ap.add_argument("--warmup-s", type=float, default=120.0,
                    help="the warm-up stops after this long once the mechanics has run")  # fmt: skip
    ap.add_argument("--work", type=Path, default=None, help="checkpoints (default: a temp dir)")
    ap.add_argument("--out", type=Path, default=RESULTS / "gpu.md")
    a = ap.parse_args(argv)
    if a.repeat < 1 or a.steps < 1 or a.warmup_steps < 1:
        ap.error("--repeat, --steps and --warmup-steps must be >= 1")
    import torch

    from diathermy.runtime import configure_threads

    configure_threads()
    t0, started = time.perf_counter(), time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    cuda = torch.cuda.is_available()
    a.out.parent.mkdir(parents=True, exist_ok=True)

    def report(inf: list[dict[str, Any]], st: list[dict[str, Any]]) -> None:
        """Write what is measured so far (a run stopped by a time limit keeps its parts)."""
        meta = {
            "command": "python benchmarks/gpu.py " + " ".join(argv),
            "machine": f"{platform.machine()}, {cores()} of {os.cpu_count()} cores",
            "torch": torch.__version__,
            "gpu": torch.cuda.get_device_name() if cuda else None,
            "started": started,
            "minutes": (time.perf_counter() - t0) / 60,
        }
        write(a.out, meta, inf, st)
        a.out.with_suffix(".json").write_text(
            json.dumps({"meta": meta, "inference": inf, "steps": st}, indent=1) + "\n"
        )

    print("inference", flush=True)
    inf = inference(a.grids, a.repeat)
    report(inf, [])
    step_grids = a.grids if a.step_grids is None else a.step_grids
    with tempfile.TemporaryDirectory() as tmp:
        work = a.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        print("whole steps", flush=True)
        for_each = partial(report, inf)
        if step_grids:
            whole_steps(step_grids, a.modes, a.steps, a.warmup_steps, a.warmup_s, work, for_each)
    print(f"wrote {a.out}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
