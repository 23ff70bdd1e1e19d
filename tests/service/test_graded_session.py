"""A session on a graded grid through the real server: the grid's node coordinates come back,
fields have the graded shape, the cut surface lies under the electrode; the SDK reads the axes."""

from __future__ import annotations

import httpx
import numpy as np

from diathermy.scene import Scene
from diathermy.service.encoding import decode_array, unpack
from diathermy_client._models import Grid as ClientGrid
from tests.service.conftest import CUT, step_until_cut

GRADED = {
    "scene": {
        **CUT["scene"],
        "name": "graded-cut",
        "resolution": {"fine_m": 1e-3, "max_cell_m": 4e-3, "margin_m": 1e-3, "depth_m": 2e-3},
    }
}


def test_graded_session_carries_its_axes(api: httpx.Client) -> None:
    r = api.post("/v1/sessions", json=GRADED)
    assert r.status_code == 201, r.text
    sid, grid = r.json()["id"], r.json()["grid"]
    expected = Scene.model_validate(GRADED["scene"]).node_grid()
    assert grid["spacing_m"] is None and tuple(grid["shape"]) == expected.shape
    for got, want in zip(grid["axes_m"], expected.axes(), strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)
    sdk = ClientGrid.model_validate(grid)
    assert not sdk.is_uniform and np.allclose(sdk.node_axes()[2], expected.axes()[2])
    step_until_cut(api, sid)
    msg = unpack(api.get(f"/v1/sessions/{sid}/fields", params={"fields": "temperature"}).content)
    assert decode_array(msg["fields"]["temperature"]).shape == expected.shape
    verts = np.array(api.get(f"/v1/sessions/{sid}/surface").json()["vertices_m"])
    assert len(verts) and np.all(np.abs(verts[:, :2] - (0.01, 0.005)) < 5e-3)
    assert verts[:, 2].min() < 0.01


def test_surface_frame_samples_fields_on_the_graded_axes() -> None:
    from diathermy.engine.simulation import Simulation
    from diathermy.service.hub import Subscription, build_payload

    sim = Simulation(Scene.model_validate(GRADED["scene"]))
    while sim.step().cut_volume_m3 == 0:
        assert sim.step_index < 30, "no cut"
    payload = build_payload(sim, Subscription(fields=("level_set",), region="surface"))
    phi = decode_array(payload["fields"]["level_set"])
    verts = decode_array(payload["surface"]["vertices"])
    assert phi.shape == (len(verts),) and len(verts) > 0
    # the surface is phi's zero set: trilinear samples there are ~0 (a fraction of a fine cell)
    assert np.abs(phi).max() < 0.5e-3
