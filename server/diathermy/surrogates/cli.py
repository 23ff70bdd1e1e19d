"""``diathermy train`` and ``diathermy evaluate``: thin argument parsing over the library.

Nothing here imports torch at module level, so building the CLI parser stays cheap; the
handlers import the training/evaluation modules when they run.
"""

from __future__ import annotations

import argparse
import json
import os
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from diathermy.surrogates.train_config import TrainConfig


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def _non_negative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text!r}")
    return value


def _fraction(text: str) -> float:
    value = _positive_float(text)
    if value >= 1:
        raise argparse.ArgumentTypeError(f"expected a fraction in (0, 1), got {text!r}")
    return value


def train_config_from_args(args: argparse.Namespace) -> TrainConfig:
    """The ``TrainConfig`` that ``diathermy train``'s parsed options describe."""
    from diathermy.surrogates.train_config import TrainConfig

    return TrainConfig(
        width=args.width,
        depth=args.depth,
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        val_fraction=args.val_fraction,
        patience=args.patience,
        seed=args.seed,
        amp=args.amp,
        device=args.device,
        num_workers=args.workers,
        per_sample_amplitude=not args.global_amplitude,
        strain_weight=args.strain_weight,
        lr_schedule=args.lr_schedule,
        energy_weight=args.energy_weight,
        scale_samples=args.scale_samples,
        mask_input=args.mask_input,
        arch=args.arch,
        levels=args.levels,
    )


def _cmd_train(args: argparse.Namespace) -> int:
    from diathermy.surrogates.data import chosen_split, read_dataset_info
    from diathermy.surrogates.training import train

    config = train_config_from_args(args)
    split = None
    if args.val_scenarios:
        split = chosen_split(read_dataset_info(args.data).complete_scenarios(), args.val_scenarios)
    result = train(
        args.data,
        args.out,
        config,
        resume=args.resume,
        split=split,
        init_from=args.init,
        progress=not args.quiet,
    )
    if int(os.environ.get("RANK", "0")) != 0:  # under torchrun only rank 0 reports
        return 0
    print(
        f"trained {result.epochs_run} epochs (best epoch {result.best_epoch}, validation "
        f"relative L2 {result.best_val_rel_l2:.4g}{', stopped early' if result.stopped_early else ''})"
        f"; validation scenarios {list(result.val_scenarios)}; model written to {result.checkpoint}"
    )
    return 0


def _print_summary(title: str, summary: dict[str, float]) -> None:
    print(
        f"{title}: {int(summary['samples'])} samples, strain-energy error mean "
        f"{summary['mean_strain_energy_error']:.4g} max {summary['max_strain_energy_error']:.4g}, "
        f"displacement relative L2 mean {summary['mean_displacement_rel_l2']:.4g}, "
        f"max abs {summary['max_displacement_abs_m']:.4g} m"
    )


def _print_baseline(baseline: dict[str, dict[str, float]]) -> None:
    """The network beside persistence, alone and patched (issue #22)."""
    print(
        "beside persistence (the previous sample of the scenario), Ritz-scaled, alone and "
        "with the patch; strain-energy error against the sample:"
    )
    for name, s in baseline.items():
        print(
            f"  {name:<15} {int(s['samples']):>5} samples  mean {s['mean_strain_energy_error']:.4g}"
            f"  max {s['max_strain_energy_error']:.4g}  cost {s['median_cost_s']:.4g} s (median)"
        )


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from dataclasses import fields

    from diathermy.surrogates.checkpoint import load_checkpoint
    from diathermy.surrogates.data import read_dataset_info
    from diathermy.surrogates.evaluation import cross_validate, evaluate_model
    from diathermy.surrogates.inference import default_device
    from diathermy.surrogates.train_config import TrainConfig

    info = read_dataset_info(args.data)
    ckpt = load_checkpoint(args.model, expected_grid=info.grid_shape)
    result: dict[str, Any]
    if args.folds is None:
        scenarios = None
        if args.subset == "validation":
            scenarios = tuple(int(s) for s in ckpt.data.get("val_scenarios", ()))
        report = evaluate_model(
            ckpt.model.to(default_device()), info.path, scenarios=scenarios,
            batch_size=args.batch_size,
        )  # fmt: skip
        _print_summary(f"{args.model} on {args.subset} scenarios", report.summary())
        result = {
            "summary": report.summary(),
            "strain_energy_error": report.strain_energy_error.tolist(),
        }
        if not args.no_baseline:
            from diathermy.surrogates.baseline import baseline_report

            baseline = baseline_report(ckpt.model, info.path, scenarios=scenarios).summary()
            _print_baseline(baseline)
            result["baseline"] = baseline
    else:
        known = {f.name for f in fields(TrainConfig)}
        stored = {k: v for k, v in ckpt.training_config.items() if k in known}
        config = TrainConfig(**stored)
        cv = cross_validate(info.path, args.folds, config, progress=not args.quiet)
        for held, report in zip(cv.held_out, cv.folds, strict=True):
            _print_summary(f"fold held out {list(held)}", report.summary())
        print(
            f"{args.folds}-fold cross-validation by scenario: strain-energy error mean "
            f"{cv.mean_strain_energy_error:.4g} max {cv.max_strain_energy_error:.4g}"
        )
        result = {
            "folds": [
                {"held_out": list(h), **r.summary()}
                for h, r in zip(cv.held_out, cv.folds, strict=True)
            ],
            "mean_strain_energy_error": cv.mean_strain_energy_error,
            "max_strain_energy_error": cv.max_strain_energy_error,
        }
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(result, fh, indent=2)
    return 0


def add_train_parser(subparsers: Any) -> None:
    """Register ``diathermy train DATA.h5 --out MODEL.pt ...``."""
    s = subparsers.add_parser("train", help="train the CNN surrogate on a mechanics dataset")
    s.add_argument("data", help="dataset file (HDF5, format diathermy-dataset)")
    s.add_argument("--out", required=True, help="model file to write (best validation weights)")
    s.add_argument("--width", type=_positive_int, default=16, help="channels (default 16)")
    s.add_argument("--depth", type=_positive_int, default=5, help="full-resolution stages (5)")
    s.add_argument("--epochs", type=_non_negative_int, default=50, help="epochs (default 50)")
    s.add_argument("--batch-size", type=_positive_int, default=4, help="per process (default 4)")
    s.add_argument("--lr", type=_positive_float, default=1e-3, help="Adam learning rate")
    s.add_argument("--val-fraction", type=_fraction, default=0.2, help="scenarios held out (0.2)")
    s.add_argument("--patience", type=_positive_int, default=10, help="early-stopping epochs")
    s.add_argument(
        "--val-scenarios", type=_non_negative_int, nargs="+", metavar="N",
        help="hold out these scenarios for validation instead of a seeded --val-fraction draw",
    )  # fmt: skip
    s.add_argument("--seed", type=int, default=0, help="split, initialisation and shuffling seed")
    s.add_argument("--resume", help="continue from a checkpoint written by train")
    s.add_argument(
        "--init", metavar="MODEL",
        help="start from this model's weights and normaliser (fine-tune on new data; fresh "
        "optimizer and split; the depth must match, a larger --width widens the model "
        "function-preservingly)",
    )  # fmt: skip
    s.add_argument(
        "--lr-schedule", choices=["constant", "cosine"], default="constant",
        help="constant, or cosine: the learning rate decays to 1/100 of --lr over the epochs",
    )  # fmt: skip
    s.add_argument("--amp", choices=["none", "bf16", "fp16"], default="none", help="autocast")
    s.add_argument("--device", default="auto", help="auto (GPU if any), cpu, cuda, cuda:1 ...")
    s.add_argument("--workers", type=_non_negative_int, default=0, help="DataLoader workers")
    s.add_argument(
        "--strain-weight", type=_non_negative_float, default=1.0,
        help="weight of the strain (displacement-difference) loss beside the L2 loss (1.0)",
    )  # fmt: skip
    s.add_argument(
        "--energy-weight", type=_non_negative_float, default=0.0,
        help="weight of the squared relative strain-energy error (the accuracy measure, eq. "
        "20/21, with E per tet from the level set) beside the other terms (0)",
    )  # fmt: skip
    s.add_argument(
        "--global-amplitude", action="store_true",
        help="scale p - p0 by one dataset-wide constant instead of each sample's max |p - p0|",
    )  # fmt: skip
    s.add_argument(
        "--scale-samples", type=_positive_int, default=256,
        help="training samples the normaliser is fitted on (256)",
    )  # fmt: skip
    s.add_argument(
        "--mask-input", action="store_true",
        help="also feed the tissue mask phi > 0 as an input channel; with --init from a model "
        "without it, the new channel starts at zero weight (the parent's predictions)",
    )  # fmt: skip
    s.add_argument(
        "--arch", choices=["pooled", "unet"], default="pooled",
        help="the network's body: pooled, the paper's (a full-resolution trunk and branches "
        "pooled by 2 and 4), or unet, a U-Net whose levels halve the grid and see it whole",
    )  # fmt: skip
    s.add_argument(
        "--levels", type=_positive_int, default=4,
        help="the U-Net's levels, 1-6 (4 spans 16 cells per axis at the bottom)",
    )  # fmt: skip
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_train)


def add_evaluate_parser(subparsers: Any) -> None:
    """Register ``diathermy evaluate MODEL.pt DATA.h5 [--folds K]``."""
    s = subparsers.add_parser(
        "evaluate", help="strain-energy and displacement errors of a CNN, or K-fold CV"
    )
    s.add_argument("model", help="model file written by diathermy train")
    s.add_argument("data", help="dataset file (HDF5, format diathermy-dataset)")
    s.add_argument(
        "--folds", type=_positive_int,
        help="K-fold cross-validation by scenario: retrain the model's config K times",
    )  # fmt: skip
    s.add_argument(
        "--subset", choices=["all", "validation"], default="all",
        help="evaluate on all complete scenarios, or the model's own validation scenarios",
    )  # fmt: skip
    s.add_argument("--batch-size", type=_positive_int, default=4)
    s.add_argument(
        "--no-baseline", action="store_true",
        help="skip the persistence baseline (the previous sample, alone and patched, beside "
        "the network alone and patched: one FEM operator per sample)",
    )  # fmt: skip
    s.add_argument("--json", help="also write the numbers to this JSON file")
    s.add_argument("--quiet", action="store_true", help="no progress bars")
    s.set_defaults(func=_cmd_evaluate)
