"""Issue #22, item 3: does a network that starts from persistence beat persistence on its own?

    python benchmarks/incremental_network.py [--train-runs 8] [--steps 60] [--epochs 12]
        [--width 16] [--batch 2] [--archs pooled unet] [--jobs N] [--device auto]
        [--data-only] [--reuse] [--work runs/incremental_network]

``--jobs``: FEM runs at once, one process each; ``--device``: where the networks train and
predict (auto: the GPU when there is one); ``--data-only``: generate the training data into
``--work`` (a later run with the same runs, steps and seed reads it back) and stop;
``--reuse``: read the networks a run with the same settings already trained into ``--work``.

One run, one grid: the `default` scene's graded grid (35x32x48, 1 mm under the electrode; the
committed results were made on its earlier 24x32x48), the grid of the set-up's main job. Training data: FEM runs (every step solved in full) of variants of
the default scene on that same grid (its working region fixed): the electrode off the centre by
up to 1.5 mm, 25-90 W, a power jump x0.4-2.5 and a 3-step pause at random steps. Every mechanics
step gives one sample (p_prev, p, u_prev, u, phi). The last two runs validate (model selection);
none is the held-out scene.

Two networks are trained on the same samples, the same epochs and the same loss (L2 of the
normalised output plus L2 of its differences along each axis, the strain): the paper-style
`direct` CNN (p - p0, phi, mask -> u; per-sample amplitude) and the `incremental` one
(``diathermy.surrogates.incremental``: the last displacement and the pressure change -> the
change of u; it starts as persistence). Held out: the `default` scene as shipped (50 W, the
centre, never generated for training), and the same with a power jump x2 at 0.9 s and the
electrode moved 1 mm at 1.35 s. Each of its mechanics steps is scored against its own FEM
answer (``relative_strain_energy_error``), alone (Ritz-scaled) and with the engine's patch:
persistence, the direct CNN, the incremental CNN fed the FEM run's last displacement, and the
incremental CNN fed its own last prediction from the direct one's first (``chained``: the networks
with no solver behind them).

Writes benchmarks/results/incremental_network.md and .json; the models go to --work.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
PREDICTORS = ("previous", "direct", "incremental", "chained")
ARCHS = {"pooled": "", "unet": "-unet"}
"""``--archs``: the networks' body (the paper's pooled layout or a U-Net) and the suffix of the
predictors' names built on it."""


def predictors(archs: list[str]) -> list[str]:
    """Persistence, then the direct, incremental and chained predictors of each architecture."""
    return ["previous"] + [f"{n}{ARCHS[a]}" for a in archs for n in PREDICTORS[1:]]


@dataclass(frozen=True)
class Variant:
    """One training (or held-out) run: electrode offset (m), power (W), events by step."""

    name: str
    offset_m: tuple[float, float] = (0.0, 0.0)
    power_w: float = 50.0
    jump_at: int = -1
    jump_factor: float = 1.0
    pause_at: int = -1
    move_at: int = -1
    move_m: tuple[float, float] = (0.0, 0.0)


def base_scene() -> Any:
    """The default scene on its own grid, its working region written out, full solves."""
    from diathermy.scene import builtin_scene
    from diathermy.scene.resolution import working_region

    scene = builtin_scene("default")
    res = scene.resolution
    region = working_region(res, scene.block_m, scene.electrodes)
    return scene.model_copy(
        update={
            "resolution": res.model_copy(update={"region_m": region}),
            "solver": scene.solver.model_copy(update={"incremental": False}),
        }
    )


def variant_scene(base: Any, v: Variant) -> Any:
    el = base.electrodes[0]
    x, y = el.position_m
    moved = el.model_copy(
        update={"position_m": (x + v.offset_m[0], y + v.offset_m[1]), "power_w": v.power_w}
    )
    return base.model_copy(update={"name": v.name, "electrodes": [moved]})


def training_variants(n: int, steps: int, seed: int) -> list[Variant]:
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        out.append(
            Variant(
                name=f"train-{i}",
                offset_m=tuple(float(d) for d in rng.uniform(-1.5e-3, 1.5e-3, 2)),  # type: ignore[arg-type]
                power_w=float(rng.uniform(25, 90)),
                jump_at=int(rng.integers(steps // 4, steps)),
                jump_factor=float(np.exp(rng.uniform(np.log(0.4), np.log(2.5)))),
                pause_at=int(rng.integers(steps // 4, steps)) if rng.uniform() < 0.5 else -1,
            )
        )
    return out


HELD_OUT = (
    Variant("default"),
    Variant("default-jump-move", jump_at=30, jump_factor=2.0, move_at=45, move_m=(1e-3, 0.0)),
)


def steps_of(
    base: Any, v: Variant, steps: int
) -> Iterator[tuple[Any, np.ndarray, dict[str, np.ndarray]]]:
    """(simulation, healthy tets, sample) after each step of ``v`` whose mechanics ran: the
    topology and the grid fields the mechanics saw and solved (p_prev, p, u_prev, u, phi)."""
    from diathermy.engine.simulation import Simulation

    sim = Simulation(variant_scene(base, v))
    shape = sim.disc.grid.shape
    name = sim.scene.electrodes[0].name
    power = v.power_w
    for k in range(steps):
        if k == v.jump_at:
            power *= v.jump_factor
            sim.set_electrode(name, power_w=power)
        if k == v.pause_at:
            sim.set_electrode(name, active=False)
        if k == v.pause_at + 3 and v.pause_at >= 0:
            sim.set_electrode(name, active=True)
        if k == v.move_at:
            x, y = sim.scene.electrodes[0].position_m
            sim.set_electrode(name, position_m=(x + v.move_m[0], y + v.move_m[1]))
        p_prev = sim.state["pressure"].reshape(shape).copy()
        u_prev = sim.state["displacement"].reshape(*shape, 3).copy()
        phi = sim.state["level_set"].reshape(shape).copy()
        healthy = ~sim.state["removed"]  # the topology this step's mechanics solves on
        rep = sim.step()
        if not rep.ran("mechanics"):
            continue
        sample = {
            "p_prev": p_prev,
            "p": sim.state["pressure"].reshape(shape).copy(),
            "u_prev": u_prev,
            "u": sim.state["displacement"].reshape(*shape, 3).copy(),
            "phi": phi,
        }
        yield sim, healthy, sample


def samples_of(job: tuple[Any, Variant, int]) -> list[dict[str, np.ndarray]]:
    """Every sample of one run (a process pool's task: its arguments in one tuple)."""
    from diathermy.runtime import configure_threads

    configure_threads()
    base, v, steps = job
    return [s for _, _, s in steps_of(base, v, steps)]


def stack(samples: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    out = {k: np.stack([s[k] for s in samples]).astype(np.float32) for k in samples[0]}
    for k in ("u", "u_prev"):
        out[k] = np.moveaxis(out[k], -1, 1)  # (S, 3, D, H, W)
    return out


def training_data(
    base: Any, variants: list[Variant], args: Any, log: Callable[[str], None]
) -> tuple[dict[str, np.ndarray], int]:
    """The stacked samples of every run (the last two runs last: validation) and the number of
    training samples; kept in ``--work`` as data.npz and reused by a run with the same runs,
    steps and seed (the FEM runs are most of a run's time)."""
    key = json.dumps([v.__dict__ for v in variants] + [args.steps], sort_keys=True)
    cache = args.work / "data.npz"
    if cache.exists():
        with np.load(cache) as f:
            if str(f["key"]) == key:
                log(f"training data from {cache}")
                return {k: f[k] for k in f.files if k not in ("key", "n_train")}, int(f["n_train"])
    per_run = []
    if args.jobs > 1:  # one FEM run per process (spawned: no torch state is inherited)
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(min(args.jobs, len(variants)), mp_context=ctx) as pool:
            jobs = [(base, v, args.steps) for v in variants]
            for v, run in zip(variants, pool.map(samples_of, jobs), strict=True):
                per_run.append(run)
                log(f"{v.name}: {len(run)} samples")
    else:
        for v in variants:
            per_run.append(samples_of((base, v, args.steps)))
            log(f"{v.name}: {len(per_run[-1])} samples")
    train = [s for run in per_run[:-2] for s in run]
    data = stack(train + [s for run in per_run[-2:] for s in run])
    np.savez(cache, key=np.array(key), n_train=np.array(len(train)), **data)
    return data, len(train)


def difference_loss(pred: Any, target: Any) -> Any:
    """L2 of the output plus L2 of its differences along each axis (the strain's proxy)."""
    import torch

    loss = torch.mean((pred - target) ** 2)
    for ax in (2, 3, 4):
        loss = loss + torch.mean((torch.diff(pred, dim=ax) - torch.diff(target, dim=ax)) ** 2)
    return loss


def train(
    model: Any,
    batch_of: Callable[[np.ndarray], tuple[Any, Any]],
    n_train: int,
    n_val: int,
    *,
    epochs: int,
    lr: float,
    batch: int,
    seed: int,
    log: Callable[[str], None],
) -> tuple[Any, list[dict[str, float]]]:
    """Adam with a cosine learning rate; keeps the weights of the best validation loss.

    ``batch_of(indices)`` -> (model output, target) for sample indices (training first, then the
    ``n_val`` validation samples)."""
    import torch

    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    n_it = epochs * max(1, n_train // batch)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, n_it, eta_min=lr / 100)
    best, best_state, history = float("inf"), None, []
    for epoch in range(epochs):
        t0 = time.perf_counter()
        model.train()
        order = rng.permutation(n_train)
        losses = []
        for i in range(0, n_train - batch + 1, batch):
            pred, target = batch_of(order[i : i + batch])
            loss = difference_loss(pred, target)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            losses.append(float(loss.detach()))
        model.eval()
        with torch.no_grad():
            val = [float(difference_loss(*batch_of(np.array([n_train + j])))) for j in range(n_val)]
        v = float(np.mean(val)) if val else float(np.mean(losses))
        history.append({"epoch": epoch + 1, "train": float(np.mean(losses)), "val": v})
        log(
            f"epoch {epoch + 1}: train {np.mean(losses):.4g} val {v:.4g} ({time.perf_counter() - t0:.0f} s)"
        )
        if v < best:
            best = v
            best_state = {k: t.detach().clone() for k, t in model.state_dict().items()}
    if best_state is not None:
        model.load_state_dict(best_state)
    return model, history


def train_direct(
    data: dict[str, np.ndarray], n_train: int, args: Any, log: Any, arch: str = "pooled"
) -> Any:
    import torch

    from diathermy.surrogates.cnn import CNNConfig, DisplacementCNN
    from diathermy.surrogates.normalization import fit_scales

    scales = fit_scales(
        data["p"][:n_train], data["phi"][:n_train], np.moveaxis(data["u"][:n_train], 1, -1),
        per_sample_amplitude=True,
    )  # fmt: skip
    config = CNNConfig(width=args.width, mask_input=True, arch=arch)
    model = DisplacementCNN(config, scales).to(args.device)
    T = {k: torch.from_numpy(v).to(args.device) for k, v in data.items()}

    def batch_of(idx: np.ndarray) -> tuple[Any, Any]:
        i = torch.from_numpy(idx).to(args.device)
        p, phi, u = T["p"][i], T["phi"][i], T["u"][i]
        x = model.normalizer.encode_inputs(p, phi)
        return model(x), model.normalizer.encode_displacement(u, p)

    n_val = len(data["p"]) - n_train
    return train(model, batch_of, n_train, n_val, epochs=args.epochs, lr=args.lr,
                 batch=args.batch, seed=args.seed, log=log)  # fmt: skip


def train_incremental(
    data: dict[str, np.ndarray], n_train: int, args: Any, log: Any, arch: str = "pooled"
) -> Any:
    import torch

    from diathermy.surrogates.incremental import (
        IncrementalCNN,
        IncrementalConfig,
        fit_change_gain,
        fit_gain,
    )

    d = {k: v[:n_train] for k, v in data.items()}
    gain = fit_gain(d["p"], d["p_prev"], d["u"], 101325.0)
    change = fit_change_gain(d["p"], d["p_prev"], d["u"], d["u_prev"], 101325.0)
    config = IncrementalConfig(
        width=args.width, gain_m_per_pa=gain, change_gain_m_per_pa=change, arch=arch
    )
    model = IncrementalCNN(config).to(args.device)
    T = {k: torch.from_numpy(v).to(args.device) for k, v in data.items()}

    def batch_of(idx: np.ndarray) -> tuple[Any, Any]:
        i = torch.from_numpy(idx).to(args.device)
        p, pp, up, phi, u = (T[k][i] for k in ("p", "p_prev", "u_prev", "phi", "u"))
        x, g = model.encode(p, pp, up, phi)
        return model(x), torch.where(g > 0, (u - up) / torch.where(g > 0, g, 1.0), 0.0)

    n_val = len(data["p"]) - n_train
    return train(model, batch_of, n_train, n_val, epochs=args.epochs, lr=args.lr,
                 batch=args.batch, seed=args.seed, log=log)  # fmt: skip


@dataclass
class Scorer:
    """Scores every predictor on the steps of one held-out run against their FEM answers."""

    nets: dict[str, tuple[Any, Any]]  # predictor-name suffix -> (direct, incremental) network
    # each chained predictor's last answer (D, H, W, 3) m
    chains: dict[str, np.ndarray] = field(default_factory=dict)
    graph: Any = None

    @staticmethod
    def predict_direct(net: Any, s: dict[str, np.ndarray]) -> np.ndarray:
        import torch

        dev = next(net.parameters()).device
        with torch.no_grad():
            u = net.predict_displacement(_tensor(s["p"], dev), _tensor(s["phi"], dev))
        return _nodal(u)

    @staticmethod
    def predict_incremental(net: Any, s: dict[str, np.ndarray], u_prev: np.ndarray) -> np.ndarray:
        import torch

        dev = next(net.parameters()).device
        fields = (s["p"], s["p_prev"], np.moveaxis(u_prev, -1, 0), s["phi"])
        with torch.no_grad():
            u = net.predict_displacement(*(_tensor(f, dev) for f in fields))
        return _nodal(u)

    def row(
        self, sim: Any, healthy: np.ndarray, s: dict[str, np.ndarray], scene: str
    ) -> dict[str, Any]:
        from diathermy.engine.backends import fem_of
        from diathermy.physics.materials import ersatz_youngs_modulus
        from diathermy.physics.predictor_errors import StepSystem, score_start
        from diathermy.physics.strain_energy import strain_energy_density

        t = sim.tissue
        solver = fem_of(sim.mechanics).solver
        E = ersatz_youngs_modulus(healthy, t.youngs_modulus_pa, t.ersatz_stiffness_ratio)
        if solver.fragments.loose.any():
            E[solver.fragments.loose] = t.ersatz_stiffness_ratio * E.max()
        system = StepSystem.of(solver, sim.state["pressure"], t.p_atm_pa, self.graph)
        self.graph = system.graph
        grads, tets, nu = sim.disc.geom.grads, sim.disc.mesh.tets, t.poisson_ratio

        def W(u: np.ndarray) -> np.ndarray:
            return strain_energy_density(grads, tets, u, E, nu)

        fns: dict[str, Callable[[], np.ndarray]] = {
            "previous": lambda: s["u_prev"].reshape(-1, 3).astype(np.float64),
        }
        u_chain: dict[str, np.ndarray] = {}

        def chained(sfx: str, direct: Any, inc: Any) -> np.ndarray:
            """The networks alone: the direct one where there is nothing before (the first
            mechanics step), then the incremental one from its own last answer, never the
            FEM's; predicted inside the timed call, so its cost is the network's."""
            last = self.chains.get(sfx)
            u = self.predict_direct(direct, s) if last is None else (
                self.predict_incremental(inc, s, last))  # fmt: skip
            u_chain[sfx] = u
            return u

        for sfx, (direct, inc) in self.nets.items():
            fns[f"direct{sfx}"] = partial(self.predict_direct, direct, s)
            fns[f"incremental{sfx}"] = partial(self.predict_incremental, inc, s, s["u_prev"])
            fns[f"chained{sfx}"] = partial(chained, sfx, direct, inc)
        row: dict[str, Any] = {
            "scene": scene,
            "step": sim.step_index,
            "max_pressure_pa": float(sim.state["pressure"].max()),
            "removed_tets": int((~healthy).sum()),
        }
        for name, fn in fns.items():
            for sc in score_start(system, name, fn, W, sim.state["strain_energy"]):
                row[f"{sc.name}_error"], row[f"{sc.name}_s"] = sc.error, sc.cost_s
        for sfx, u in u_chain.items():
            self.chains[sfx] = system.start("chained", u).u.reshape(s["u_prev"].shape)
        return row


def _tensor(a: np.ndarray, device: Any) -> Any:
    import torch

    return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32))[None].to(device)


def _nodal(u_grid: Any) -> np.ndarray:
    """(1, 3, D, H, W) tensor on any device -> (n_nodes, 3) float64."""
    return np.moveaxis(u_grid[0].cpu().numpy(), 0, -1).reshape(-1, 3).astype(np.float64)


def score_held_out(
    base: Any, v: Variant, steps: int, nets: dict[str, tuple[Any, Any]]
) -> list[dict]:
    """Every predictor on every mechanics step of held-out ``v`` against its FEM answer
    (``nets``: as :class:`Scorer`'s)."""
    scorer = Scorer(nets)
    return [scorer.row(sim, h, s, v.name) for sim, h, s in steps_of(base, v, steps)]


def score_from_files(
    job: tuple[Any, Variant, int, dict[str, tuple[Path, Path]], str],
) -> list[dict]:
    """:func:`score_held_out` with the networks read from their files (a process pool's task)."""
    import torch

    from diathermy.runtime import configure_threads
    from diathermy.surrogates.cnn import DisplacementCNN
    from diathermy.surrogates.incremental import IncrementalCNN

    configure_threads()
    torch.set_num_threads(1)
    base, v, steps, files, device = job
    nets = {}
    for sfx, (fd, fi) in files.items():
        pair = []
        for cls, f in ((DisplacementCNN, fd), (IncrementalCNN, fi)):
            saved = torch.load(f, map_location=device, weights_only=True)
            model = cls.from_constructor_args(saved["constructor_args"])
            model.load_state_dict(saved["state"])
            pair.append(model.to(device).eval())
        nets[sfx] = (pair[0], pair[1])
    return score_held_out(base, v, steps, nets)


def summarise(rows: list[dict], names: list[str]) -> list[dict]:
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        rs = [r for r in rows if r["scene"] == scene]
        for name in names:
            for suffix in ("", "+patch"):
                key = f"{name}{suffix}"
                e = [r[f"{key}_error"] for r in rs]
                c = [r[f"{key}_s"] for r in rs]
                out.append({
                    "scene": scene, "predictor": key, "steps": len(rs),
                    "max": max(e), "mean": float(np.mean(e)), "median_s": statistics.median(c),
                })  # fmt: skip
    return out


def write_report(out: Path, meta: dict, summary: list[dict], rows: list[dict]) -> None:
    def pct(x: float) -> str:
        return f"{100 * x:.3g} %"

    lines = [
        "# The incremental network against persistence (issue #22, item 3)",
        "",
        f"`{meta['command']}` on {meta['machine']}, started {meta['started']}; whole run "
        f"{meta['minutes']:.1f} min. Grid {meta['grid']} (the `default` scene's graded grid). "
        f"Training: {meta['train_runs']} FEM runs of {meta['steps']} steps "
        f"({meta['n_train']} samples, {meta['n_val']} validation samples from the last two runs), "
        f"width {meta['width']}, {meta['epochs']} epochs, batch {meta['batch']}, lr {meta['lr']} "
        "(cosine); training "
        + ", ".join(f"{m:.1f} min ({k})" for k, m in meta["train_minutes"].items())
        + ". Held out: "
        + ", ".join(f"`{v.name}`" for v in HELD_OUT)
        + " (see the script's docstring).",
        "",
        "Strain-energy error of every mechanics step against the FEM solve of that step (max / "
        "mean over the steps) and the median cost per step (prediction, Ritz scale, patch). "
        "`previous`: persistence; `direct`: the paper-style CNN; `incremental`: the new network "
        "fed the FEM run's last displacement; `chained`: the networks alone, the direct one on "
        "the first mechanics step and then the incremental one fed its own last answer. "
        "`-unet`: the same on a U-Net body (`diathermy.surrogates.unet`) instead of the "
        "paper's pooled layout.",
        "",
        "| scene | predictor | steps | max | mean | median s |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for s in summary:
        lines.append(
            f"| {s['scene']} | {s['predictor']} | {s['steps']} | {pct(s['max'])} | "
            f"{pct(s['mean'])} | {s['median_s']:.3f} |"
        )
    lines += ["", "Training history (loss of the normalised output and its differences):", ""]
    lines += ["| model | epoch | train | validation |", "|---|---:|---:|---:|"]
    for model, history in meta["history"].items():
        for h in history:
            lines.append(f"| {model} | {h['epoch']} | {h['train']:.4g} | {h['val']:.4g} |")
    lines += ["", "Per step (error %):", ""]
    keys = [f"{n}{s}" for n in meta["predictors"] for s in ("", "+patch")]
    lines += ["| scene | step | p max MPa | removed | " + " | ".join(keys) + " |"]
    lines += ["|---|---:|---:|---:|" + "---:|" * len(keys)]
    for r in rows:
        vals = " | ".join(f"{100 * r[f'{k}_error']:.3g}" for k in keys)
        lines.append(
            f"| {r['scene']} | {r['step']} | {r['max_pressure_pa'] / 1e6:.2f} | "
            f"{r['removed_tets']} | {vals} |"
        )
    lines += [
        "",
        "In the engine (`in_the_engine`): the default scene built and stepped with "
        "`mechanics.predictor: previous`, and with `auto` asking each direct network written "
        "above on the first mechanics step; per mechanics step the predictor, mode, CG "
        "iterations and wall time.",
        "",
        "| model | build s | step | predictor | mode | CG iterations | mechanics s |",
        "|---|---:|---:|---|---|---:|---:|",
    ]
    for run in meta.get("engine", []):
        for st in run["steps"]:
            lines.append(
                f"| {run['model'] or '- (previous)'} | {run['build_s']:.2f} | {st['step']} | "
                f"{st['predictor']} | {st['mode']} | {st['iterations']} | {st['wall_s']:.3f} |"
            )
    notes = out.with_name(out.stem + "_notes.md")
    if notes.exists():
        lines += ["", notes.read_text().rstrip()]
    out.write_text("\n".join(lines) + "\n")


def model_checkpoint(
    args: Any, base: Any, arch: str, summary: list[dict], rows: list[dict]
) -> Path:
    """The trained direct network of ``arch`` as a checkpoint for the scene's graded grid
    (``--work``/cnn_<nz>x<ny>x<nx>[-unet].pt, its node coordinates in it, so the engine's
    ``mechanics.predictor: auto`` can ask it there), with its held-out errors against
    persistence as metrics: over every step and on the first mechanics step of each held-out
    run, where 'auto' asks it."""
    import torch

    from diathermy.surrogates.checkpoint import save_checkpoint
    from diathermy.surrogates.cnn import DisplacementCNN

    sfx = ARCHS[arch]
    saved = torch.load(args.work / f"direct{sfx}.pt", map_location="cpu", weights_only=True)
    model = DisplacementCNN.from_constructor_args(saved["constructor_args"])
    model.load_state_dict(saved["state"])
    grid = base.node_grid()
    first = {}
    for scene in dict.fromkeys(r["scene"] for r in rows):
        r = next(r for r in rows if r["scene"] == scene)
        first[scene] = {k: r[f"{k}_error"] for k in ("previous", "previous+patch",
                                                     f"direct{sfx}", f"direct{sfx}+patch")}  # fmt: skip
    held_out = [s for s in summary if s["predictor"].startswith(("previous", f"direct{sfx}"))]
    shape = "x".join(map(str, grid.shape))
    path = args.work / f"cnn_{shape}{sfx}.pt"
    save_checkpoint(
        path, model, grid_shape=grid.shape, spacing_m=grid.min_spacing_m, axes_m=grid.axes(),
        training_config={"benchmark": "incremental_network.py", "arch": arch,
                         "width": args.width, "epochs": args.epochs, "batch": args.batch,
                         "lr": args.lr, "seed": args.seed},
        metrics={"held_out": held_out, "first_mechanics_step": first},
        data={"train_runs": args.train_runs, "steps": args.steps, "scene": "default",
              "held_out_scenes": [v.name for v in HELD_OUT]},
    )  # fmt: skip
    return path


def settings_of(args: Any) -> dict[str, Any]:
    """What else than the architecture decides a trained network: data and optimisation."""
    keys = ("train_runs", "steps", "seed", "epochs", "batch", "lr", "width")
    return {k: getattr(args, k) for k in keys}


def trained_before(
    path: Path, kind: str, arch: str, args: Any
) -> tuple[Any, list[dict[str, float]], float] | None:
    """``--reuse``: the network of ``path`` with its history and training minutes when it was
    trained with this run's settings and architecture, else None (it is trained again)."""
    import torch

    from diathermy.surrogates.cnn import DisplacementCNN
    from diathermy.surrogates.incremental import IncrementalCNN

    if not path.exists():
        return None
    saved = torch.load(path, map_location=args.device, weights_only=True)
    config = saved["constructor_args"]["config"]
    if config.get("arch", "pooled") != arch or config["width"] != args.width:
        return None
    if saved.get("settings", settings_of(args)) != settings_of(args):
        return None
    cls = DisplacementCNN if kind == "direct" else IncrementalCNN
    model = cls.from_constructor_args(saved["constructor_args"])
    model.load_state_dict(saved["state"])
    return model.to(args.device), list(saved.get("history", [])), float(saved.get("minutes", 0.0))


def in_the_engine(model: Path | None, steps: int = 3) -> dict[str, Any]:
    """The shipped default scene on its grid, built and stepped until ``steps`` mechanics steps
    ran, with ``mechanics.predictor`` 'previous' (``model`` None) or 'auto' asking ``model``
    where persistence has nothing: the build time and each mechanics step's predictor, mode, CG
    iterations and wall time (what the network's start buys the engine)."""
    from diathermy.engine.simulation import Simulation
    from diathermy.scene import builtin_scene

    scene = builtin_scene("default")
    mech = (
        {"predictor": "previous"} if model is None else {"predictor": "auto", "model": str(model)}
    )
    scene = scene.model_copy(update={"mechanics": scene.mechanics.model_copy(update=mech)})
    t0 = time.perf_counter()
    sim = Simulation(scene)
    out: dict[str, Any] = {"model": None if model is None else model.name,
                           "build_s": time.perf_counter() - t0, "steps": []}  # fmt: skip
    while len(out["steps"]) < steps and sim.step_index < 60:
        e = sim.step().effects["mechanics"]
        if e.ran:
            out["steps"].append({"step": sim.step_index, "predictor": e.extra.get("predictor"),
                                 "mode": e.extra.get("mode"), "iterations": e.iterations,
                                 "wall_s": e.wall_s})  # fmt: skip
    return out


def device_name(device: str) -> str:
    import torch

    if device.startswith("cuda"):
        return f"{torch.cuda.get_device_name(torch.device(device))} (torch {torch.__version__})"
    return f"the CPU (torch {torch.__version__})"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--train-runs", type=int, default=8)
    ap.add_argument("--steps", type=int, default=60, help="steps per run (training and held out)")
    ap.add_argument("--epochs", type=int, default=12)
    ap.add_argument("--width", type=int, default=16)
    ap.add_argument("--batch", type=int, default=2)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1, help="torch threads for the training")
    ap.add_argument("--jobs", type=int, default=1, help="FEM runs at once (processes)")
    ap.add_argument("--device", default="auto", help="torch device of the networks (auto: "
                    "the GPU when there is one)")  # fmt: skip
    ap.add_argument("--archs", nargs="+", choices=list(ARCHS), default=["pooled"],
                    help="the networks' bodies: each trains a direct and an incremental network")  # fmt: skip
    ap.add_argument("--reuse", action="store_true",
                    help="read networks already trained in --work with the same settings instead "
                    "of training them again (a run cut off after training)")  # fmt: skip
    ap.add_argument("--data-only", action="store_true",
                    help="generate (or find) the training data in --work and stop")  # fmt: skip
    ap.add_argument("--work", type=Path, default=Path("runs/incremental_network"))
    ap.add_argument("--out", type=Path, default=RESULTS / "incremental_network.md")
    args = ap.parse_args(argv)
    if args.train_runs < 3 or args.steps < 4 or args.epochs < 1 or args.width < 1 or args.jobs < 1:
        ap.error("need --train-runs >= 3, --steps >= 4, --epochs >= 1, --width >= 1, --jobs >= 1")
    import torch

    if args.device == "auto":
        args.device = "cuda" if torch.cuda.is_available() else "cpu"
    if args.device.startswith("cuda") and not torch.cuda.is_available():
        ap.error(f"--device {args.device}: CUDA is not available")

    from diathermy.runtime import configure_threads

    configure_threads()
    torch.set_num_threads(max(1, args.threads))
    t_start, started = time.perf_counter(), time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    args.work.mkdir(parents=True, exist_ok=True)

    def log(msg: str) -> None:
        print(f"[{time.perf_counter() - t_start:7.1f} s] {msg}", flush=True)

    base = base_scene()
    variants = training_variants(args.train_runs, args.steps, args.seed)
    data, n_train = training_data(base, variants, args, log)
    if args.data_only:
        log(f"training data in {args.work / 'data.npz'}: {len(data['p'])} samples")
        return 0
    n_val = len(data["p"]) - n_train
    nets: dict[str, tuple[Any, Any]] = {}
    history: dict[str, list[dict[str, float]]] = {}
    minutes: dict[str, float] = {}
    for arch in args.archs:
        sfx = ARCHS[arch]
        pair = []
        for kind, fit in (("direct", train_direct), ("incremental", train_incremental)):
            name, path = f"{kind}{sfx}", args.work / f"{kind}{sfx}.pt"
            reused = trained_before(path, kind, arch, args) if args.reuse else None
            if reused is not None:
                model, history[name], minutes[name] = reused
                log(f"{name}: trained before, read from {path}")
            else:
                t0 = time.perf_counter()
                log(f"training {name}")
                model, history[name] = fit(data, n_train, args, log, arch)
                minutes[name] = (time.perf_counter() - t0) / 60
                torch.save({"constructor_args": model.constructor_args(),
                            "state": model.state_dict(), "settings": settings_of(args),
                            "history": history[name], "minutes": minutes[name]}, path)  # fmt: skip
            pair.append(model.eval())
        nets[sfx] = (pair[0], pair[1])
    rows = []
    if args.jobs > 1:  # each held-out run in a process of its own, the networks read back
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        del nets
        files = {ARCHS[a]: (args.work / f"direct{ARCHS[a]}.pt", args.work / f"incremental{ARCHS[a]}.pt")
                 for a in args.archs}  # fmt: skip
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(min(args.jobs, len(HELD_OUT)), mp_context=ctx) as pool:
            jobs = [(base, v, args.steps, files, args.device) for v in HELD_OUT]
            for v, got in zip(HELD_OUT, pool.map(score_from_files, jobs), strict=True):
                rows += got
                log(f"held out {v.name}: {len(got)} steps")
    else:
        for v in HELD_OUT:
            rows += score_held_out(base, v, args.steps, nets)
            log(f"held out {v.name}: {sum(r['scene'] == v.name for r in rows)} steps")
    names = predictors(args.archs)
    summary = summarise(rows, names)
    grid = "x".join(str(n) for n in data["p"].shape[1:])
    engine: list[dict[str, Any]] = [in_the_engine(None)]
    for arch in args.archs:
        path = model_checkpoint(args, base, arch, summary, rows)
        log(f"the direct{ARCHS[arch]} network as a model for the engine's grid: {path}")
        engine.append(in_the_engine(path))
    meta = {
        "command": "python benchmarks/incremental_network.py "
        f"--train-runs {args.train_runs} --steps {args.steps} --epochs {args.epochs} "
        f"--width {args.width} --batch {args.batch} --jobs {args.jobs} "
        f"--archs {' '.join(args.archs)}",
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, FEM runs {args.jobs} at "
        f"once, networks on {device_name(args.device)}, torch on {args.threads} thread(s)",
        "started": started,
        "minutes": (time.perf_counter() - t_start) / 60,
        "grid": grid, "train_runs": args.train_runs, "steps": args.steps,
        "n_train": n_train, "n_val": n_val, "width": args.width,
        "epochs": args.epochs, "batch": args.batch, "lr": args.lr, "archs": args.archs,
        "predictors": names, "train_minutes": minutes, "history": history, "engine": engine,
        "variants": [v.__dict__ for v in variants],
    }  # fmt: skip
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_report(args.out, meta, summary, rows)
    args.out.with_suffix(".json").write_text(
        json.dumps({"meta": meta, "summary": summary, "rows": rows}, indent=1) + "\n"
    )
    log(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
