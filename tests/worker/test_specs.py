"""Job specs: bad input names its field; the training options mirror TrainConfig."""

from __future__ import annotations

from dataclasses import fields

import pytest

from diathermy.surrogates.train_config import TrainConfig
from diathermy.worker.specs import JobSpecError, TrainOptions, spec_from_dict
from diathermy.worker.training_job import torchrun_command


def test_train_options_mirror_train_config() -> None:
    assert set(TrainOptions.model_fields) == {f.name for f in fields(TrainConfig)}
    defaults = TrainOptions().model_dump()
    assert defaults == {f.name: getattr(TrainConfig(), f.name) for f in fields(TrainConfig)}


@pytest.mark.parametrize(
    ("spec", "field"),
    [
        ({"kind": "dataset", "config": {"grid": [2, 5, 9]}}, "config.grid"),
        ({"kind": "dataset", "config": {"n_scenarios": 0}}, "config.n_scenarios"),
        ({"kind": "dataset", "config": {}, "scheduler": "tcp://x:1"}, "scheduler"),
        ({"kind": "training", "dataset": "j-1", "train": {"width": 0}}, "train.width"),
        ({"kind": "training", "dataset": "j-1", "model_name": "A B"}, "model_name"),
        ({"kind": "training", "dataset": "j-1", "nproc_per_node": 2}, "nproc_per_node"),
        ({"kind": "nope"}, "kind"),
    ],
)
def test_bad_specs_name_the_field(spec: dict, field: str) -> None:
    with pytest.raises(JobSpecError) as err:
        spec_from_dict(spec)
    assert str(err.value).startswith(f"{field}: "), str(err.value)


def test_torchrun_command_passes_every_option(tmp_path) -> None:
    """Every TrainConfig field set off its default survives the trip through the trainer's CLI."""
    import argparse

    from diathermy.surrogates.cli import add_train_parser, train_config_from_args

    config = TrainConfig(
        width=4, depth=3, epochs=3, batch_size=2, lr=0.01, val_fraction=0.3, patience=5,
        seed=9, amp="bf16", device="cpu", num_workers=1, scale_samples=17,
        per_sample_amplitude=False, strain_weight=0.25, lr_schedule="cosine", energy_weight=0.5,
        mask_input=True, arch="unet", levels=3,
    )  # fmt: skip
    defaults = TrainConfig()
    assert all(getattr(config, f.name) != getattr(defaults, f.name) for f in fields(TrainConfig))
    cmd = torchrun_command(
        tmp_path / "d.h5", tmp_path / "m.pt", config, nproc_per_node=2, resume=tmp_path / "m.pt"
    )
    assert cmd[1:5] == ["-m", "torch.distributed.run", "--standalone", "--nproc_per_node=2"]
    parser = argparse.ArgumentParser()
    add_train_parser(parser.add_subparsers())
    args = parser.parse_args(cmd[cmd.index("train") :])
    assert train_config_from_args(args) == config
    assert args.resume == str(tmp_path / "m.pt")
