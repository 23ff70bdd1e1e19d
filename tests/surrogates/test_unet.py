"""The U-Net body and the paper-style network built on it: any grid size, what one node's input
reaches, checkpoints of version 3, and what only the paper's layout can do."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from diathermy.surrogates.checkpoint import load_checkpoint, save_checkpoint
from diathermy.surrogates.cnn import CNNConfig, DisplacementCNN
from diathermy.surrogates.inference import predict
from diathermy.surrogates.unet import UNet3D


@pytest.mark.parametrize("shape", [(24, 32, 48), (5, 6, 7), (1, 3, 9), (17, 17, 33)])
def test_any_grid_keeps_its_size(shape: tuple[int, int, int]) -> None:
    net = UNet3D(3, 4, 4, 0.01).eval()
    with torch.no_grad():
        y = net(torch.randn(2, 3, *shape))
    assert y.shape == (2, 4, *shape)
    assert torch.isfinite(y).all()


def test_one_node_reaches_the_whole_block() -> None:
    """A change at one corner node moves the output at the opposite corner: the receptive field
    spans the block (the paper's 3^5 trunk with branches pooled by 2 and 4 does not, at 33 cells).
    In float64: four averaging levels shrink the change by 8^4, below float32's resolution."""
    torch.manual_seed(0)
    shape = (17, 17, 33)
    unet = UNet3D(2, 4, 4, 0.01).double().eval()
    paper = DisplacementCNN(CNNConfig(width=4)).double().eval()
    x = torch.randn(1, 2, *shape, dtype=torch.float64)
    x2 = x.clone()
    x2[0, :, 0, 0, 0] += 10.0
    with torch.no_grad():
        far_unet = (unet(x2) - unet(x))[0, :, -1, -1, -1].abs().max()
        far_paper = (paper(x2) - paper(x))[0, :, -1, -1, -1].abs().max()
    assert float(far_unet) > 0.0
    assert float(far_paper) == 0.0


def test_unet_checkpoint_is_version_3_and_loads_back(tmp_path: Path) -> None:
    torch.manual_seed(1)
    model = DisplacementCNN(CNNConfig(width=4, mask_input=True, arch="unet", levels=3)).eval()
    path = tmp_path / "unet.pt"
    save_checkpoint(path, model, grid_shape=(9, 9, 17), spacing_m=(0.01,) * 3)
    assert torch.load(path, weights_only=True)["format_version"] == 3
    loaded = load_checkpoint(path, expected_grid=(9, 9, 17)).model
    assert loaded.config == model.config
    rng = np.random.default_rng(0)
    p = 101325.0 + 1e5 * rng.random((9, 9, 17))
    phi = 1e-3 * rng.standard_normal((9, 9, 17))
    np.testing.assert_array_equal(predict(loaded, p, phi), predict(model, p, phi))


def test_old_configurations_still_build_the_paper_layout() -> None:
    """A checkpoint's config written before ``arch`` existed builds the paper's network."""
    args = DisplacementCNN(CNNConfig(width=4)).constructor_args()
    args["config"] = {k: v for k, v in args["config"].items() if k not in ("arch", "levels")}
    model = DisplacementCNN.from_constructor_args(args)
    assert model.config.arch == "pooled" and hasattr(model, "branch4")


def test_paper_layout_only_operations_refuse_a_unet() -> None:
    model = DisplacementCNN(CNNConfig(width=4, arch="unet", levels=2))
    with pytest.raises(ValueError, match="paper's layout only"):
        model.widened(8)
    with pytest.raises(ValueError, match="paper's layout only"):
        model.with_mask_input()


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"arch": "transformer"}, "arch must be one of"),
    ({"arch": "unet", "levels": 7}, "levels"),
])  # fmt: skip
def test_bad_architectures_are_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        CNNConfig(**kwargs)
    with pytest.raises(ValueError, match="width and levels"):
        UNet3D(2, 0, 3, 0.01)
