"""The parameters of the dissection law, in one place (PHYSICS.md section 4).

The scene's ``LevelSetConfig`` takes its defaults from here, and the engine and the dataset
generator both step with a ``LevelSetLaw`` built from it. A light module (no solver imports),
so that scene validation stays fast.
"""

from __future__ import annotations

from dataclasses import dataclass

V0_M_PER_S = 5e-3
"""Front speed scale v0 in m/s: F = v0 (W / kappa - 1) where W > kappa."""
CFL = 0.5
"""Sub-step Courant number, dt_sub max F (1/dx + 1/dy + 1/dz) <= cfl (the scheme is monotone
up to 1)."""
REINIT_EVERY = 10
"""Re-initialise phi to a signed distance every this many dissection steps (steps that moved
the front; steps skipped because W < kappa everywhere do not count)."""
REINIT_BAND_CELLS = 6.0
"""Half-width of the re-initialised band around the front, in cells of the largest spacing
there (on a graded grid the largest cell around the removed region), worked on around the
removed region only (at 64x64x128 nodes the whole block takes ~0.6 s
against ~15 ms for a small crater)."""
NONLOCAL_LENGTH_M = 0.0
"""Material length l in m over which the strain energy driving the front is averaged
(``nonlocal_average``); 0 is the local law of PHYSICS.md section 4."""
MAX_SUBSTEPS = 10_000
"""Sub-steps one physical step may take before ``advance`` gives up."""


@dataclass(frozen=True)
class LevelSetLaw:
    """The dissection law of a run: front speed scale v0 (m/s), damage threshold kappa
    (J/m^3), CFL number of the sub-steps, re-initialisation every this many dissection steps,
    and the material length (m) of the non-local driver (0: local)."""

    v0_m_per_s: float
    kappa_j_per_m3: float
    cfl: float
    reinit_every: int
    nonlocal_length_m: float = NONLOCAL_LENGTH_M
