"""``diathermy train`` / ``evaluate`` from the command line: results and one-line errors."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from diathermy.cli import main
from diathermy.surrogates import load_checkpoint


def test_train_writes_a_checkpoint(
    tiny_dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "model.pt"
    argv = ["train", str(tiny_dataset), "--out", str(out), "--epochs", "2", "--width", "4",
            "--depth", "2", "--seed", "1", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    assert "trained 2 epochs" in capsys.readouterr().out
    ckpt = load_checkpoint(out, expected_grid=(9, 9, 17))
    assert ckpt.model.config.width == 4 and ckpt.training_config["seed"] == 1
    assert main([*argv[:-1], "--epochs", "3", "--resume", str(out), "--quiet"]) == 0
    assert load_checkpoint(out).training_state["epoch"] == 3  # type: ignore[index]


def test_train_holds_out_the_named_scenarios_and_fine_tunes(
    tiny_dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    base, tuned = tmp_path / "base.pt", tmp_path / "tuned.pt"
    common = ["--width", "4", "--depth", "2", "--quiet", "--val-scenarios", "1", "4"]
    assert main(["train", str(tiny_dataset), "--out", str(base), "--epochs", "1", *common]) == 0
    assert "validation scenarios [1, 4]" in capsys.readouterr().out
    assert load_checkpoint(base).data["train_scenarios"] == [0, 2, 3, 5]
    argv = ["train", str(tiny_dataset), "--out", str(tuned), "--epochs", "1", "--init", str(base),
            "--lr-schedule", "cosine", *common]  # fmt: skip
    assert main(argv) == 0
    ckpt = load_checkpoint(tuned)
    assert ckpt.training_config["lr_schedule"] == "cosine" and ckpt.data["val_scenarios"] == [1, 4]
    assert main([*argv, "--out", str(tmp_path / "mask.pt"), "--mask-input"]) == 0
    masked = load_checkpoint(tmp_path / "mask.pt")
    assert masked.model.config.mask_input and masked.training_config["mask_input"]


def test_train_a_unet_and_fine_tune_it(tiny_dataset: Path, tmp_path: Path) -> None:
    """--arch unet trains a U-Net (checkpoint version 3); a fine-tune keeps its arch, and one
    that asks for another arch or a wider U-Net is a one-line refusal."""
    out, tuned = tmp_path / "unet.pt", tmp_path / "tuned.pt"
    common = ["--width", "4", "--epochs", "1", "--quiet", "--arch", "unet", "--levels", "2"]
    assert main(["train", str(tiny_dataset), "--out", str(out), *common]) == 0
    ckpt = load_checkpoint(out, expected_grid=(9, 9, 17))
    assert (ckpt.model.config.arch, ckpt.model.config.levels) == ("unet", 2)
    assert ckpt.training_config["arch"] == "unet"
    assert main(["train", str(tiny_dataset), "--out", str(tuned), *common, "--init", str(out)]) == 0
    assert load_checkpoint(tuned).model.config.arch == "unet"
    pooled = ["--width", "4", "--epochs", "1", "--quiet", "--init", str(out)]
    wider = [*common[2:], "--width", "8", "--init", str(out)]
    for argv, message in ((pooled, "arch 'unet'"), (wider, "only the paper's layout")):
        done = subprocess.run(
            [sys.executable, "-m", "diathermy", "train", str(tiny_dataset), "--out",
             str(tmp_path / "bad.pt"), *argv],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        assert done.returncode != 0 and message in done.stderr, done.stderr
        assert "Traceback" not in done.stderr


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["train", "missing.h5", "--out", "m.pt"], "does not exist"),
        (["train", "DATA", "--out", "m.pt", "--arch", "unet", "--levels", "9"], "levels"),
        (["train", "DATA", "--out", "m.pt", "--width", "0"], "positive integer"),
        (["train", "DATA", "--out", "m.pt", "--val-fraction", "1.5"], "fraction"),
        (["train", "DATA", "--out", "m.pt", "--amp", "fp16", "--device", "cpu"], "fp16"),
        (["train", "DATA", "--out", "m.pt", "--device", "cuda:7"], "CUDA"),
        (["train", "DATA", "--out", "m.pt", "--val-scenarios", "3", "99"], "[99]"),
        (
            ["train", "DATA", "--out", "m.pt", "--val-scenarios", "0", "1", "2", "3", "4", "5"],
            "at least one",
        ),
        (["train", "DATA", "--out", "m.pt", "--init", "missing.pt"], "does not exist"),
        (["train", "DATA", "--out", "m.pt", "--lr-schedule", "step"], "invalid choice"),
        (
            ["train", "DATA", "--out", "m.pt", "--resume", "m.pt", "--val-scenarios", "1"],
            "keeps its checkpoint's scenario split",
        ),
        (["evaluate", "DATA", "DATA"], "not a readable diathermy CNN checkpoint"),
        (["evaluate", "missing.pt", "DATA"], "does not exist"),
    ],
)
def test_errors_are_one_line(
    argv: list[str], message: str, tiny_dataset: Path, tmp_path: Path,
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:  # fmt: skip
    monkeypatch.chdir(tmp_path)
    argv = [str(tiny_dataset) if a == "DATA" else a for a in argv]
    if argv[0] == "train" and "--device" in argv and "cuda" in argv[-1]:
        monkeypatch.setattr("torch.cuda.is_available", lambda: False)
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse errors exit with status 2
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1] and "error:" in err[-1]
    assert "Traceback" not in "\n".join(err)


def test_building_the_parser_does_not_import_torch() -> None:
    code = "import sys; from diathermy.cli import build_parser; build_parser(); print('torch' in sys.modules)"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    )
    assert proc.stdout.strip() == "False"


def test_evaluate_reports_strain_energy_errors(
    tiny_dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    out = tmp_path / "model.pt"
    argv = ["train", str(tiny_dataset), "--out", str(out), "--epochs", "1", "--width", "4",
            "--depth", "2", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    report = tmp_path / "eval.json"
    assert main(["evaluate", str(out), str(tiny_dataset), "--subset", "validation",
                 "--json", str(report)]) == 0  # fmt: skip
    out_text = capsys.readouterr().out
    assert "strain-energy error mean" in out_text and "beside persistence" in out_text
    data = json.loads(report.read_text())
    assert data["summary"]["samples"] == 8  # 2 validation scenarios x 4 steps
    base = data["baseline"]  # the persistence rows beside the network's, alone and patched
    assert set(base) == {"cnn", "cnn+patch", "previous", "previous+patch"}
    assert base["cnn"]["samples"] == 8 and base["previous"]["samples"] == 6  # no first samples
    assert all(b["median_cost_s"] >= 0 for b in base.values())
    assert all(e >= 0 for e in data["strain_energy_error"])
    assert main(["evaluate", str(out), str(tiny_dataset), "--folds", "2", "--quiet"]) == 0
    assert "2-fold cross-validation by scenario" in capsys.readouterr().out
