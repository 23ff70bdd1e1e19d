"""Drag a high-power electrode across a small tissue block until it cuts, and save a picture.

    python examples/moving_electrode.py --url http://127.0.0.1:8000 --token secret [--out cut.png]

The URL and token default to $DIATHERMY_URL and $DIATHERMY_TOKEN. Needs only the SDK
(diathermy_client) and matplotlib. The block is 2 x 1 x 1 cm on a coarse grid under 200 W, so a
cut appears within a few steps; the electrode moves 0.5 mm along x before each step.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from diathermy_client import Client  # noqa: E402

SCENE = {
    "name": "moving-electrode-demo",
    "block_m": [0.02, 0.01, 0.01],
    "electrodes": [{"name": "active", "position_m": [0.006, 0.005], "power_w": 200.0}],
}


def run(
    url: str | None, token: str | None, grid: tuple[int, int, int], out: Path, max_steps: int
) -> dict:
    """Step a moving-electrode session until it cuts (and a little more); plot the cut."""
    with Client(url, token) as client, client.create_session(scene=SCENE, grid=grid) as session:
        x, y = 0.006, 0.005
        first_cut = None
        for _ in range(max_steps):
            session.move_electrode(x, y)
            report = session.step().reports[-1]
            x = min(x + 5e-4, 0.014)
            if report.cut_volume_m3 and first_cut is None:
                first_cut = report.step
            if first_cut is not None and report.step >= first_cut + 2:
                break
        if first_cut is None:
            raise SystemExit(f"no cut within {max_steps} steps")
        fields = session.fields(["level_set", "temperature"], dtype="float64")
        surface = session.surface()
        plot(fields.arrays, fields.grid, y, surface.vertices_m, out)
        return {
            "step": fields.step,
            "first_cut": first_cut,
            "surface_vertices": len(surface.vertices_m),
        }


def plot(arrays: dict[str, np.ndarray], grid, y_m: float, vertices: np.ndarray, out: Path) -> None:  # noqa: ANN001
    """Cross-sections at the electrode's y: the level set (cut outlined) and the temperature."""
    nz, ny, nx = grid.shape
    dx, dy, dz = grid.spacing_m
    j = int(round((y_m - grid.origin_m[1]) / dy))
    xs = grid.origin_m[0] + dx * np.arange(nx)
    zs = grid.origin_m[2] + dz * np.arange(nz)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.2), constrained_layout=True)
    for ax, name, label in [
        (axes[0], "level_set", "level set phi (m): < 0 removed"),
        (axes[1], "temperature", "temperature (K)"),
    ]:
        img = ax.pcolormesh(xs * 1e3, zs * 1e3, arrays[name][:, j, :], shading="gouraud")
        ax.contour(xs * 1e3, zs * 1e3, arrays["level_set"][:, j, :], levels=[0.0], colors="w")
        fig.colorbar(img, ax=ax, label=label)
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("z (mm)")
        ax.set_aspect("equal")
    near = vertices[np.abs(vertices[:, 1] - y_m) < dy] if len(vertices) else vertices
    if len(near):
        axes[0].plot(near[:, 0] * 1e3, near[:, 2] * 1e3, "k.", ms=3, label="cut surface")
        axes[0].legend(loc="lower right", fontsize=7)
    fig.suptitle(f"cross-section at y = {y_m * 1e3:.1f} mm")
    fig.savefig(out, dpi=120)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--url", default=os.environ.get("DIATHERMY_URL"))
    ap.add_argument("--token", default=os.environ.get("DIATHERMY_TOKEN"))
    ap.add_argument("--grid", default="9x9x17", help="nodes NZxNYxNX")
    ap.add_argument("--out", type=Path, default=Path("cut.png"))
    ap.add_argument("--max-steps", type=int, default=40)
    args = ap.parse_args()
    grid = tuple(int(v) for v in args.grid.split("x"))
    result = run(args.url, args.token, grid, args.out, args.max_steps)  # type: ignore[arg-type]
    print(f"cut from step {result['first_cut']}; picture at step {result['step']}: {args.out}")


if __name__ == "__main__":
    main()
