"""Run a scene to its end, writing the run file (and optional VTU series) with a progress bar."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from tqdm import tqdm

from diathermy.engine.backends import ModelResolver
from diathermy.engine.runfile import RunWriter
from diathermy.engine.simulation import Simulation
from diathermy.engine.vtu import write_pvd
from diathermy.scene import Scene


@dataclass(frozen=True)
class RunSummary:
    """What a finished run did, for the CLI's closing line."""

    scene: str
    steps: int
    time_s: float
    wall_s: float
    out: Path
    max_temperature_k: float
    max_pressure_pa: float
    cut_volume_m3: float
    crater_depth_m: float
    left_fine_region: dict[str, tuple[float, float]] = field(default_factory=dict)
    """What reached beyond the graded grid's working region: name -> (the first time it did,
    in s; the farthest it reached beyond, in m)."""
    left_out: dict[str, tuple[float, str]] = field(default_factory=dict)
    """Effects the scene leaves out that would have acted: name -> (the first time, in s; why,
    at the last step that said so)."""

    def __str__(self) -> str:
        return (
            f"{self.scene}: {self.steps} steps to t = {self.time_s:.3f} s in {self.wall_s:.1f} s wall; "
            f"T_max {self.max_temperature_k:.1f} K, p_max {self.max_pressure_pa / 1e3:.1f} kPa, "
            f"cut {self.cut_volume_m3 * 1e9:.2f} mm^3, crater {self.crater_depth_m * 1e3:.2f} mm "
            f"-> {self.out}"
        )

    def warnings(self) -> list[str]:
        """One line on what left the fine working region and one per left-out effect that
        would have acted; empty when neither happened."""
        lines = []
        if self.left_fine_region:
            parts = ", ".join(
                f"the {name} from t = {t:.2f} s (up to {far * 1e3:.2f} mm beyond)"
                for name, (t, far) in self.left_fine_region.items()
            )
            lines.append(
                f"warning: {self.scene}: {parts} left the grid's fine working region, so results "
                "there are on coarser cells; deepen resolution.depth_m (or add a deep tier, "
                "resolution.deep_m) or widen resolution.region_m"
            )
        for name, (t, why) in self.left_out.items():
            lines.append(
                f"warning: {self.scene}: the scene leaves out {name}, which would act from "
                f"t = {t:.2f} s: {why}; add it to effects, or drive the electrode less hard"
            )
        return lines


def track_fine_region(
    left: dict[str, tuple[float, float]], time_s: float, beyond_m: dict[str, float]
) -> None:
    """Fold one step's ``StepReport.beyond_fine_region_m`` into ``left`` (see ``RunSummary``)."""
    for name, far in beyond_m.items():
        if far > 0:
            first, farthest = left.get(name, (time_s, 0.0))
            left[name] = (first, max(farthest, far))


def track_left_out(
    left_out: dict[str, tuple[float, str]], time_s: float, acting: dict[str, str]
) -> None:
    """Fold one step's ``StepReport.left_out_effects`` into ``left_out`` (see ``RunSummary``)."""
    for name, why in acting.items():
        left_out[name] = (left_out.get(name, (time_s, why))[0], why)


def run_scene(
    scene: Scene,
    *,
    out: Path,
    vtu_dir: Path | None = None,
    every: int = 1,
    progress: bool = True,
    models: ModelResolver | None = None,
) -> RunSummary:
    """Build the simulation, advance it ``scene.steps`` steps, write every k-th step.

    ``models`` looks up surrogate model names (see ``engine.backends``)."""
    sim = Simulation(scene, models=models)
    pvd: list[tuple[float, str]] = []
    wall = 0.0
    tmax = pmax = 0.0
    left: dict[str, tuple[float, float]] = {}
    left_out: dict[str, tuple[float, str]] = {}
    with RunWriter(out, sim.grid, scene.model_dump_json()) as writer:
        bar = tqdm(total=scene.steps, disable=not progress, unit="step", desc=scene.name)
        for _ in range(scene.steps):
            report = sim.step()
            wall += report.wall_s
            tmax = max(tmax, report.max_temperature_k)
            pmax = max(pmax, report.max_pressure_pa)
            track_fine_region(left, report.time_s, report.beyond_fine_region_m)
            track_left_out(left_out, report.time_s, report.left_out_effects)
            if sim.step_index % every == 0 or sim.step_index == scene.steps:
                writer.append(
                    time_s=sim.time_s,
                    step=sim.step_index,
                    fields=sim.nodal_fields(),
                    cell_fields=sim.cell_fields(),
                    report=report.to_dict(),
                )
                if vtu_dir is not None:
                    name = f"step_{sim.step_index:05d}.vtu"
                    sim.write_vtu(vtu_dir / name)
                    pvd.append((sim.time_s, name))
                    if "dissection" in sim.effects:
                        sim.write_cut_surface(vtu_dir / f"cut_{sim.step_index:05d}.vtu")
            bar.set_postfix(
                P=f"{report.delivered_power_w:.1f}W",
                Tmax=f"{report.max_temperature_k:.0f}K",
                pmax=f"{report.max_pressure_pa / 1e3:.0f}kPa",
                cut=f"{report.cut_volume_m3 * 1e9:.1f}mm3",
            )
            bar.update()
        bar.close()
    if vtu_dir is not None and pvd:
        write_pvd(vtu_dir / f"{scene.name}.pvd", pvd)
    last = sim.last_report
    return RunSummary(
        scene=scene.name,
        steps=sim.step_index,
        time_s=sim.time_s,
        wall_s=wall,
        out=out,
        max_temperature_k=tmax,
        max_pressure_pa=pmax,
        cut_volume_m3=last.cut_volume_m3 if last else 0.0,
        crater_depth_m=last.crater_depth_m if last else 0.0,
        left_fine_region=left,
        left_out=left_out,
    )
