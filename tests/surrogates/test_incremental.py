"""The incremental network: persistence before training, exact proportionality to the
overpressure, checkpoint round trip, and its bad configurations."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from diathermy.surrogates.incremental import (
    IncrementalCNN,
    IncrementalConfig,
    fit_change_gain,
    fit_gain,
)

P0 = 101325.0
SHAPE = (5, 6, 7)


def _fields(seed: int = 0) -> tuple[torch.Tensor, ...]:
    g = torch.Generator().manual_seed(seed)
    p_prev = P0 + 2e5 * torch.rand((2, *SHAPE), generator=g)
    p_new = p_prev + 5e4 * torch.randn((2, *SHAPE), generator=g)
    u_prev = 1e-4 * torch.randn((2, 3, *SHAPE), generator=g)
    phi = 1e-3 * torch.randn((2, *SHAPE), generator=g)
    return p_new, p_prev, u_prev, phi


ARCH = {
    "pooled": {"depth": 2, "pools": (2, 4)},
    "unet": {"arch": "unet", "levels": 3},
}


def _trained_looking(seed: int = 1, arch: str = "pooled") -> IncrementalCNN:
    """A model whose output layer is not zero (as after training)."""
    torch.manual_seed(seed)
    model = IncrementalCNN(IncrementalConfig(width=4, gain_m_per_pa=1e-9, **ARCH[arch]))
    torch.nn.init.normal_(model.out.weight, std=0.3)
    return model.eval()


@pytest.mark.parametrize("arch", ARCH)
def test_an_untrained_model_is_persistence(arch: str) -> None:
    model = IncrementalCNN(IncrementalConfig(width=4, **ARCH[arch])).eval()
    p_new, p_prev, u_prev, phi = _fields()
    with torch.no_grad():
        u = model.predict_displacement(p_new, p_prev, u_prev, phi)
    assert torch.equal(u, u_prev)


@pytest.mark.parametrize("arch", ARCH)
@pytest.mark.parametrize("c", [1e-3, 0.5, 7.0])
def test_the_change_is_proportional_to_the_overpressure(c: float, arch: str) -> None:
    """Scaling every overpressure and u_prev by c scales the predicted change by c (the
    mechanics is linear in p - p0 for a fixed topology)."""
    model = _trained_looking(arch=arch)
    p_new, p_prev, u_prev, phi = _fields()
    with torch.no_grad():
        d1 = model.predict_displacement(p_new, p_prev, u_prev, phi) - u_prev
        d2 = model.predict_displacement(P0 + c * (p_new - P0), P0 + c * (p_prev - P0),
                                        c * u_prev, phi) - c * u_prev  # fmt: skip
    assert float(d1.abs().max()) > 0.0
    # float32 inputs scaled by c round differently: 1e-4 of the largest change
    torch.testing.assert_close(d2, c * d1, rtol=1e-4, atol=1e-4 * float(d1.abs().max()))


def test_no_overpressure_and_no_displacement_predicts_no_change() -> None:
    model = _trained_looking()
    zero_p = torch.full((1, *SHAPE), P0)
    with torch.no_grad():
        u = model.predict_displacement(zero_p, zero_p, torch.zeros((1, 3, *SHAPE)),
                                       torch.ones((1, *SHAPE)))  # fmt: skip
    assert torch.equal(u, torch.zeros_like(u))


@pytest.mark.parametrize("arch", ARCH)
def test_constructor_args_rebuild_the_same_model(arch: str) -> None:
    model = _trained_looking(arch=arch)
    again = IncrementalCNN.from_constructor_args(model.constructor_args())
    again.load_state_dict(model.state_dict())
    p_new, p_prev, u_prev, phi = _fields(3)
    with torch.no_grad():
        a = model.predict_displacement(p_new, p_prev, u_prev, phi)
        b = again.eval().predict_displacement(p_new, p_prev, u_prev, phi)
    assert torch.equal(a, b)
    assert again.config == model.config


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"width": 0}, "width and depth"),
        ({"depth": 0}, "width and depth"),
        ({"pools": (1,)}, "pools"),
        ({"gain_m_per_pa": 0.0}, "gain_m_per_pa"),
        ({"level_set_scale_m": float("nan")}, "level_set_scale_m"),
        ({"arch": "resnet"}, "arch must be one of"),
        ({"arch": "unet", "levels": 0}, "levels"),
    ],
)
def test_bad_configurations_are_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        IncrementalConfig(**kwargs)


def test_fit_gain_is_max_displacement_per_pa() -> None:
    p_prev = np.full((2, *SHAPE), P0)
    p_new = p_prev.copy()
    p_new[0, 0, 0, 0] += 1e5
    p_new[1, 1, 1, 1] += 2e5
    u = np.zeros((2, 3, *SHAPE))
    u[0, 2, 0, 0, 0] = 1e-4  # 1e-9 m/Pa
    u[1, 0, 1, 1, 1] = -2e-4  # 1e-9 m/Pa
    assert fit_gain(p_new, p_prev, u, P0) == pytest.approx(1e-9)
    assert fit_gain(p_prev, p_prev, u, P0) == 1e-9  # nothing above p0: the floor


def test_fit_change_gain_is_max_change_per_pa() -> None:
    p_prev = np.full((1, *SHAPE), P0)
    p_new = p_prev.copy()
    p_new[0, 2, 2, 2] += 1e5
    u_prev = np.zeros((1, 3, *SHAPE))
    u_prev[0, 1, 3, 3, 3] = 5e-5
    u_new = u_prev.copy()
    u_new[0, 1, 3, 3, 3] += 1e-5  # a change of 1e-5 m at 1e5 Pa: 1e-10 m/Pa
    assert fit_change_gain(p_new, p_prev, u_new, u_prev, P0) == pytest.approx(1e-10)
    assert fit_gain(p_new, p_prev, u_new, P0) == pytest.approx(6e-10)


def test_the_output_uses_the_change_gain() -> None:
    """The same weights with a 10x change gain predict a 10x change."""
    model = _trained_looking()
    args = model.constructor_args()
    args["config"]["change_gain_m_per_pa"] *= 10.0
    big = IncrementalCNN.from_constructor_args(args)
    big.load_state_dict(model.state_dict())
    p_new, p_prev, u_prev, phi = _fields(5)
    with torch.no_grad():
        d1 = model.predict_displacement(p_new, p_prev, u_prev, phi) - u_prev
        d10 = big.eval().predict_displacement(p_new, p_prev, u_prev, phi) - u_prev
    torch.testing.assert_close(d10, 10.0 * d1, rtol=1e-4, atol=1e-15)
