"""The CNN's shapes, its normaliser and its checkpoints."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from diathermy.errors import CheckpointError
from diathermy.surrogates import (
    CNNConfig,
    DisplacementCNN,
    FieldScales,
    load_checkpoint,
    predict,
    save_checkpoint,
)
from diathermy.surrogates.normalization import fit_scales


def _fields(grid: tuple[int, int, int], seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return 101325.0 + 1e4 * rng.random(grid), 1e-2 * rng.standard_normal(grid)


@pytest.mark.parametrize("grid", [(9, 9, 17), (8, 8, 16), (5, 7, 6), (3, 3, 3), (2, 4, 9)])
def test_output_has_the_input_grid_shape(grid: tuple[int, int, int]) -> None:
    torch.manual_seed(0)
    model = DisplacementCNN(CNNConfig(width=4, depth=3))
    p, phi = _fields(grid)
    u = predict(model, p, phi)
    assert u.shape == (*grid, 3) and u.dtype == np.float32 and np.all(np.isfinite(u))
    batch = predict(model, np.stack([p, p]), np.stack([phi, phi]))
    assert batch.shape == (2, *grid, 3)
    np.testing.assert_allclose(batch[0], u, rtol=1e-5, atol=1e-12)


def test_odd_paper_sized_grid_forward() -> None:
    model = DisplacementCNN(CNNConfig(width=2, depth=2))
    x = torch.zeros(1, 2, 33, 33, 65)
    assert model(x).shape == (1, 3, 33, 33, 65)


def test_branches_reach_beyond_the_trunk_receptive_field() -> None:
    # With depth 1 the full-resolution trunk sees +-1 node; the pooled-by-4 branch sees further.
    torch.manual_seed(0)
    model = DisplacementCNN(CNNConfig(width=4, depth=1)).eval()
    x = torch.zeros(1, 2, 16, 16, 16)
    x2 = x.clone()
    x2[0, 0, 0, 0, 0] = 1.0
    with torch.no_grad():
        diff = (model(x2) - model(x)).abs()[0].sum(0)
    assert diff[8, 8, 8] > 0  # 8 nodes away: only the pooled branches can carry it


def test_normaliser_maps_physical_units() -> None:
    scales = FieldScales(p0_pa=1e5, pressure_scale_pa=2e3, level_set_scale_m=0.5e-2,
                         displacement_scale_m=3e-5)  # fmt: skip
    model = DisplacementCNN(CNNConfig(width=2, depth=1), scales)
    p = torch.full((1, 2, 2, 2), 1e5 + 4e3)
    phi = torch.full((1, 2, 2, 2), 1e-2)
    x = model.normalizer.encode_inputs(p, phi)
    assert torch.allclose(x[:, 0], torch.full_like(p, 2.0))
    assert torch.allclose(x[:, 1], torch.full_like(p, 2.0))
    y = torch.ones(1, 3, 2, 2, 2)
    assert torch.allclose(model.normalizer.decode_displacement(y, p), 3e-5 * y)
    assert "normalizer.pressure_scale_pa" in model.state_dict()


def test_per_sample_amplitude_makes_the_prediction_linear_in_the_overpressure() -> None:
    """u is linear in p - p0 for a fixed topology: the amplitude-normalised model is exactly so."""
    scales = FieldScales(p0_pa=1e5, pressure_scale_pa=1e6, level_set_scale_m=1e-2,
                         displacement_scale_m=1e-4, per_sample_amplitude=True)  # fmt: skip
    torch.manual_seed(0)
    model = DisplacementCNN(CNNConfig(width=4, depth=2), scales).eval()
    shape = (5, 6, 7)
    bump = torch.rand(1, *shape)
    phi = torch.rand(1, *shape) * 1e-2
    with torch.no_grad():
        u1 = model.predict_displacement(1e5 + 2e5 * bump, phi)
        u7 = model.predict_displacement(1e5 + 7 * 2e5 * bump, phi)  # far outside any training
        u0 = model.predict_displacement(torch.full((1, *shape), 1e5), phi)
    assert u1.abs().max() > 0
    assert torch.allclose(u7, 7 * u1, rtol=1e-5, atol=0)
    assert torch.count_nonzero(u0) == 0  # no overpressure, no displacement (no NaN from 0/0)
    x = model.normalizer.encode_inputs(1e5 + 2e5 * bump, phi)
    assert float(x[:, 0].abs().max()) == pytest.approx(1.0)
    # encode/decode of u are inverses under the same pressure
    u = torch.randn(1, 3, *shape)
    p = 1e5 + 3e5 * bump
    back = model.normalizer.decode_displacement(model.normalizer.encode_displacement(u, p), p)
    assert torch.allclose(back, u, rtol=1e-5)
    # the flag is a constructor argument: it survives a rebuild from constructor_args
    rebuilt = DisplacementCNN.from_constructor_args(model.constructor_args())
    assert rebuilt.normalizer.per_sample_amplitude


def test_fit_scales_per_sample_amplitude_measures_u_at_the_reference_amplitude() -> None:
    shape = (3, 4, 5)
    base = np.random.default_rng(0).random((*shape, 3))
    amps = np.array([1e5, 4e5, 0.0])
    p = 101325.0 + amps[:, None, None, None] * np.ones((3, *shape))
    u = amps[:, None, None, None, None] * 1e-9 * base[None]  # linear in the amplitude
    s = fit_scales(p, np.ones((3, *shape)), u, per_sample_amplitude=True)
    assert s.per_sample_amplitude
    assert s.pressure_scale_pa == pytest.approx(np.sqrt((1e10 + 16e10) / 2))
    expected = np.sqrt(np.mean(np.square(s.pressure_scale_pa * 1e-9 * base)))
    assert s.displacement_scale_m == pytest.approx(expected, rel=1e-9)


def test_invalid_config_is_refused() -> None:
    with pytest.raises(ValueError, match="width"):
        CNNConfig(width=0)
    with pytest.raises(ValueError, match="pressure_scale_pa"):
        FieldScales(pressure_scale_pa=0.0)


def _saved(tmp_path: Path, grid: tuple[int, int, int] = (9, 9, 17)) -> tuple[Path, DisplacementCNN]:
    torch.manual_seed(3)
    scales = FieldScales(pressure_scale_pa=5e3, level_set_scale_m=2e-3, displacement_scale_m=1e-5)
    model = DisplacementCNN(CNNConfig(width=4, depth=2, negative_slope=0.05), scales)
    path = tmp_path / "m.pt"
    save_checkpoint(path, model, grid_shape=grid, spacing_m=(0.0125, 0.0125, 0.0125),
                    training_config={"lr": 1e-3}, metrics={"best_val_loss": 0.5})  # fmt: skip
    return path, model


def test_checkpoint_round_trip_gives_identical_outputs(tmp_path: Path) -> None:
    path, model = _saved(tmp_path)
    loaded = load_checkpoint(path, expected_grid=(9, 9, 17))
    assert loaded.model.config == model.config
    assert loaded.model.normalizer.scales() == model.normalizer.scales()
    assert loaded.grid_shape == (9, 9, 17) and loaded.metrics == {"best_val_loss": 0.5}
    p, phi = _fields((9, 9, 17), seed=1)
    np.testing.assert_array_equal(predict(loaded.model, p, phi), predict(model.eval(), p, phi))
    # plain content: loads with the safe unpickler
    assert isinstance(torch.load(path, weights_only=True), dict)


def test_checkpoint_for_another_grid_is_refused(tmp_path: Path) -> None:
    path, _ = _saved(tmp_path)
    with pytest.raises(CheckpointError, match=r"trained for grid 9x9x17.*33x33x65"):
        load_checkpoint(path, expected_grid=(33, 33, 65))


def test_corrupt_foreign_and_future_files_are_refused(tmp_path: Path) -> None:
    path, _ = _saved(tmp_path)
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(path.read_bytes()[:200])
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a checkpoint at all")
    foreign = tmp_path / "foreign.pt"
    torch.save({"state_dict": {}, "epoch": 3}, foreign)
    future = tmp_path / "future.pt"
    payload = torch.load(path, weights_only=True)
    payload["format_version"] = 99
    torch.save(payload, future)
    broken = tmp_path / "broken.pt"
    payload = torch.load(path, weights_only=True)
    del payload["state_dict"]["out.weight"]
    torch.save(payload, broken)
    cases = {
        truncated: "corrupt",
        garbage: "corrupt",
        foreign: "foreign",
        future: "version 99",
        broken: "corrupt checkpoint",
        tmp_path / "missing.pt": "does not exist",
    }
    for bad, message in cases.items():
        with pytest.raises(CheckpointError, match=message) as info:
            load_checkpoint(bad)
        assert "\n" not in str(info.value)


def test_mask_channel_widening_keeps_the_prediction_and_the_mask_then_matters(
    tmp_path: Path,
) -> None:
    torch.manual_seed(0)
    model = DisplacementCNN(CNNConfig(width=4, depth=2)).eval()
    wide = model.with_mask_input().eval()
    assert wide.config.mask_input and wide.stem.conv.weight.shape[1] == 3
    assert not torch.any(wide.stem.conv.weight[:, 2])  # the new channel starts at zero weight
    p, phi = _fields((9, 9, 17), seed=2)
    np.testing.assert_array_equal(predict(wide, p, phi), predict(model, p, phi))
    # once the mask weights are not zero, the output changes where phi changes sign, and only
    # through that sign: phi scaled by a positive factor keeps the mask
    with torch.no_grad():
        wide.stem.conv.weight[:, 2] = 0.3
    assert not np.allclose(predict(wide, p, phi), predict(model, p, phi))
    flip = phi.copy()
    flip[:, :, :8] = np.abs(flip[:, :, :8])  # cut nodes become tissue at the same |phi|
    base, after = predict(wide, p, phi), predict(wide, p, flip)
    plain = predict(model, p, flip) - predict(model, p, phi)
    assert not np.allclose(after - base, plain)
    # version 2 on disk for a mask model, version 1 still for a plain one; both load back
    save_checkpoint(tmp_path / "wide.pt", wide, grid_shape=(9, 9, 17), spacing_m=(0.01,) * 3)
    save_checkpoint(tmp_path / "plain.pt", model, grid_shape=(9, 9, 17), spacing_m=(0.01,) * 3)
    assert torch.load(tmp_path / "wide.pt", weights_only=True)["format_version"] == 2
    assert torch.load(tmp_path / "plain.pt", weights_only=True)["format_version"] == 1
    loaded = load_checkpoint(tmp_path / "wide.pt").model
    assert loaded.config.mask_input
    np.testing.assert_array_equal(predict(loaded, p, phi), base)
    assert not load_checkpoint(tmp_path / "plain.pt").model.config.mask_input


def test_widening_keeps_the_prediction_and_breaks_the_copies_symmetry() -> None:
    torch.manual_seed(1)
    model = DisplacementCNN(CNNConfig(width=4, depth=3)).eval()
    p, phi = _fields((9, 9, 17), seed=3)
    ref = predict(model, p, phi)
    exact = model.widened(7, noise=0.0).eval()
    assert exact.config.width == 7 and exact.n_parameters() > model.n_parameters()
    np.testing.assert_allclose(
        predict(exact, p, phi), ref, rtol=1e-5, atol=1e-6 * np.abs(ref).max()
    )
    noisy = model.widened(7, noise=1e-3, seed=2).eval()
    change = np.linalg.norm(predict(noisy, p, phi) - ref) / np.linalg.norm(ref)
    assert 0 < change < 1e-2
    w = noisy.trunk[0].conv.weight  # each copy differs from every old channel it could copy
    assert all(not torch.equal(w[j], w[i]) for j in range(4, 7) for i in range(4))
    assert model.widened(4, noise=0.0).n_parameters() == model.n_parameters()
    with pytest.raises(ValueError, match="narrow"):
        model.widened(3)


@pytest.mark.parametrize("kernel", [1, 3])
@pytest.mark.parametrize("channels_last", [False, True])
def test_direct_onednn_conv_matches_the_reference(kernel: int, channels_last: bool) -> None:
    """The inference fast path against the plain F.conv3d twin (PyTorch's generic route)."""
    from torch.nn import functional as F

    from diathermy.surrogates.layers import _use_onednn_directly, conv3d_same

    torch.manual_seed(0)
    x = torch.randn(1, 5, 7, 6, 9)
    w, b = torch.randn(4, 5, kernel, kernel, kernel), torch.randn(4)
    if channels_last:
        x = x.contiguous(memory_format=torch.channels_last_3d)
    with torch.inference_mode():
        assert _use_onednn_directly(x, w)
        fast = conv3d_same(x, w, b)
    ref = F.conv3d(x, w, b, padding=kernel // 2)
    assert fast.shape == ref.shape == (1, 4, 7, 6, 9)
    torch.testing.assert_close(fast, ref, rtol=1e-4, atol=1e-4)


def test_training_mode_keeps_autograd() -> None:
    from diathermy.surrogates.layers import _use_onednn_directly

    w = torch.randn(2, 2, 3, 3, 3, requires_grad=True)
    assert not _use_onednn_directly(torch.randn(1, 2, 4, 4, 4), w)
    model = DisplacementCNN(CNNConfig(width=2, depth=1))
    model(torch.randn(1, 2, 5, 5, 5)).sum().backward()
    assert model.stem.conv.weight.grad is not None
