"""Reading electrodes back: where each one is and how it is driven, at the session's current time.

The scene gives each electrode a position (or a path), a drive and an on/off schedule; front ends
change them at run time (``PATCH .../electrodes/{name}``, stream ``electrode`` messages). This is
the one place that answers "where is it now", e.g. for a viewer that draws the electrode.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field

from diathermy.engine.electrodes import electrode_pose
from diathermy.service.engine_process import RemoteSim
from diathermy.service.exceptions import NotFoundError
from diathermy.service.registry import SessionRecord, SessionRegistry
from diathermy.service.sessions import run_locked


class ElectrodeState(BaseModel):
    """One electrode at the session's current time, run-time changes applied."""

    name: str
    # a list, not a tuple: schemathesis rejects the prefixItems of a tuple in a response schema
    position_m: list[float] = Field(
        min_length=2, max_length=2, description="(x, y) on the top surface, m"
    )
    radius_m: float = Field(description="contact disk radius, m")
    drive: Literal["power", "current_density"]
    power_w: float = Field(description="set power, W (used when drive is 'power')")
    current_density_a_per_m2: float = Field(
        description="set current density, A/m^2 (used when drive is 'current_density')"
    )
    max_voltage_v: float | None = Field(
        description="the generator's voltage limit, V rms (from the scene; null: none)"
    )
    active: bool = Field(description="switched on now (the schedule and run-time switch applied)")
    follows_path: bool = Field(
        description="the position comes from the scene's path (it moves with time) rather than "
        "from a fixed or run-time position"
    )
    control_id: int = Field(description="the session's last control id when this was read")
    step: int
    time_s: float


class ElectrodeList(BaseModel):
    electrodes: list[ElectrodeState]


def electrode_states(sim: Any, control_id: int) -> list[ElectrodeState]:
    """Every electrode of ``sim`` as it stands at ``sim.time_s`` (engine process)."""
    out = []
    for el in sim.scene.electrodes:
        override = sim.state.overrides.get(el.name)
        pose = electrode_pose(el, float(sim.time_s), override)
        out.append(
            ElectrodeState(
                name=pose.name,
                position_m=list(pose.position_m),
                radius_m=pose.radius_m,
                drive="current_density" if pose.drive == "current_density" else "power",
                power_w=pose.power_w,
                current_density_a_per_m2=pose.current_density_a_per_m2,
                max_voltage_v=pose.max_voltage_v,
                active=pose.active,
                follows_path=el.path is not None
                and (override is None or override.position_m is None),
                control_id=control_id,
                step=int(sim.step_index),
                time_s=float(sim.time_s),
            )
        )
    return out


async def read_electrodes(
    *, registry: SessionRegistry, rec: SessionRecord, name: str | None = None
) -> list[ElectrodeState]:
    """All electrodes of a session, or the one called ``name`` (NotFoundError, HTTP 404)."""

    def read(sim: RemoteSim) -> list[ElectrodeState]:
        states: list[ElectrodeState] = sim.call(electrode_states, rec.control_id)
        if name is None:
            return states
        chosen = [s for s in states if s.name == name]
        if not chosen:
            names = ", ".join(s.name for s in states) or "none"
            raise NotFoundError(f"no electrode {name!r}; electrodes: {names}", field="name")
        return chosen

    return await run_locked(rec, registry, read)
