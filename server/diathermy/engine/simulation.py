"""The simulation a session holds: a scene, the state of every field, and a step that runs
exactly the effects the scene calls for.

One step (dt from the scene) runs, in this order and only where called for:
electric -> thermal -> vaporization (EOS) -> mechanics -> dissection -> thermal damage.
Besides the effects a scene leaves out, a step skips work that provably changes nothing and says
why in its report: no active electrode (no electric solve), the potential of an unchanged
conductivity and contact (reused), no node above saturation (p = p0, no EOS), p = p0 everywhere
(u = 0, no mechanics solve), W below kappa everywhere (no level-set update).
"""

from __future__ import annotations

import os
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np

from diathermy.engine.discretization import Discretization, build_discretization
from diathermy.engine.electrodes import ElectrodeOverride, ElectrodePose, electrode_pose
from diathermy.engine.report import EffectReport, StepReport
from diathermy.engine.state import CELL_FIELDS, NODAL_FIELDS, SimulationState, initial_state
from diathermy.errors import SceneError
from diathermy.fem.edges import edge_stiffness
from diathermy.mesh import Grid
from diathermy.physics.cut_surface import CutSurface, cut_surface, write_cut_surface
from diathermy.physics.electric import (
    ContactWeights,
    DrivenPotential,
    ElectrodeDrive,
    PotentialSolver,
    contact_weights,
    joule_heat,
)
from diathermy.physics.electrothermal import ElectroThermal
from diathermy.physics.eos import local_energy_balance
from diathermy.physics.levelset import (
    advance,
    front_speed,
    initial_level_set,
    reinitialize,
    tet_to_node,
    volume_incidence,
)
from diathermy.physics.mechanics_backend import FEMBackend, MechanicsBackend
from diathermy.physics.properties import (
    effective_conductivity,
    nodes_to_tets,
    volumetric_heat_capacity,
    water_mass_density,
)
from diathermy.physics.strain_energy import strain_energy_density
from diathermy.physics.thermal import HeatEnergy, HeatStepper, heat_mesh
from diathermy.physics.tissue_effects import (
    ArrheniusDamage,
    ConductivityLaw,
    arrhenius_damage_increment,
    electrical_conductivity,
)
from diathermy.physics.topology import (
    REMOVED_FRACTION,
    Topology,
    contact_height,
    evaluate_topology,
)
from diathermy.report.budget import resolve_accuracy_budget
from diathermy.scene import Scene


class Simulation:
    """State and stepping of one scene. Not thread-safe: one caller steps it at a time."""

    def __init__(self, scene: Scene, *, mechanics_backend: MechanicsBackend | None = None) -> None:
        scene = resolve_accuracy_budget(scene)
        self.scene = scene
        self.tissue = scene.material
        self.effects: tuple[str, ...] = scene.closed_effects
        self.disc: Discretization = build_discretization(scene.grid, scene.block_m)
        mesh, geom = self.disc.mesh, self.disc.geom
        self.top_z = float(self.disc.grid.origin_m[2] + self.disc.grid.size_m[2])
        self._rho_c_step: np.ndarray | None = None
        self.state: SimulationState = initial_state(
            mesh.n_nodes, mesh.n_tets, mesh.points[:, 2], self.top_z, self.tissue
        )
        self.state["level_set"] = initial_level_set(self.disc.grid).ravel().copy()
        self.calls: Counter[str] = Counter()
        self.last_report: StepReport | None = None
        stiffness = edge_stiffness(geom, mesh.tets, mesh.n_nodes)
        self.potential = DrivenPotential(
            # hierarchies rebuilt from the current operator: a restored run repeats the original
            PotentialSolver(mesh, stiffness, rtol=scene.solver.electric_rtol, stale_factor=0.0)
        )
        self.heat = HeatStepper(
            heat_mesh(mesh, geom, stiffness),
            h_w_per_m2_k=self.tissue.h_convective_w_per_m2_k,
            t_ambient_k=self.tissue.t_ambient_k,
            rtol=scene.solver.thermal_rtol,
            amg_stale_factor=0.0,  # rebuild from the current operator: restarts stay bitwise
        )
        # the paper's monolithic option shares the potential and heat solvers above
        self.coupled = ElectroThermal(
            mesh, geom, stiffness=stiffness, potential=self.potential, heat=self.heat
        )
        self._monolithic: tuple[np.ndarray, ContactWeights, ElectrodeDrive] | None = None
        self.conductivity_law = ConductivityLaw()
        self.damage_law = ArrheniusDamage()
        self._contacts: dict[tuple[float, ...], ContactWeights] = {}
        self._mechanics = mechanics_backend
        if (
            mechanics_backend is None
            and scene.mechanics.backend != "fem"
            and ("mechanics" in self.effects)
        ):
            self._mechanics = make_backend(self)  # a missing or wrong model fails here, not later
        self._steps_since_reinit = 0
        self._last_mech_key: tuple[bytes, bytes] | None = None
        self._incidence = None  # node-tet volume incidence, built on the first cut
        self.topology: Topology | None = None

    # ------------------------------------------------------------------ public API
    @property
    def grid(self) -> Grid:
        return self.disc.grid

    @property
    def step_index(self) -> int:
        return self.state.step

    @property
    def time_s(self) -> float:
        return self.state.time_s

    @property
    def mechanics(self) -> MechanicsBackend:
        """The mechanics backend (FEM unless the scene or caller chose a surrogate)."""
        if self._mechanics is None:
            self._mechanics = make_backend(self)
        return self._mechanics

    def dof_counts(self) -> dict[str, int]:
        """Unknowns per field of this scene's effects."""
        n = self.disc.n_nodes
        out = {}
        if "electric" in self.effects:
            out["potential"] = n - self.disc.bottom_nodes.size
        if "thermal" in self.effects:
            out["temperature"] = n
        if "mechanics" in self.effects:
            out["displacement"] = 3 * (n - self.disc.bottom_nodes.size)
        if "dissection" in self.effects:
            out["level_set"] = n
        return out

    def field_names(self) -> list[str]:
        return [*NODAL_FIELDS, "displacement", *CELL_FIELDS]

    def field(self, name: str) -> np.ndarray:
        """A copy of one field: nodal grid-shaped (nz, ny, nx[, 3]) or per tet (n_tets,)."""
        if name not in self.field_names():
            raise SceneError(f"unknown field {name!r}; fields: {', '.join(self.field_names())}")
        value = self.state[name]
        if name in CELL_FIELDS:
            return value.copy()
        return self.disc.to_grid(value).copy()

    def nodal_fields(self) -> dict[str, np.ndarray]:
        """The fields of the scene's effects, grid-shaped, for run files."""
        names = ["temperature"] if "thermal" in self.effects else []
        if "electric" in self.effects:
            names.insert(0, "potential")
        if "vaporization" in self.effects:
            names += ["pressure", "vapor_fraction"]
        if "mechanics" in self.effects:
            names.append("displacement")
        if "dissection" in self.effects:
            names.append("level_set")
        if "thermal_damage" in self.effects:
            names.append("thermal_damage")
        return {n: self.field(n) for n in names}

    def cell_fields(self) -> dict[str, np.ndarray]:
        out = {}
        if "electric" in self.effects:
            out["joule_heat"] = self.state["joule_heat"].copy()
        if "mechanics" in self.effects:
            out["strain_energy"] = self.state["strain_energy"].copy()
        if "dissection" in self.effects:
            out["removed"] = self.state["removed"].astype(np.uint8)
        return out

    def cut_surface(self) -> tuple[np.ndarray, np.ndarray]:
        """The phi = 0 surface: vertices (n, 3) in m and triangles (m, 3)."""
        surf: CutSurface = cut_surface(self.disc.to_grid(self.state["level_set"]), self.grid)
        return surf.vertices, surf.faces

    def set_electrode(
        self,
        name: str,
        *,
        position_m: tuple[float, float] | None = None,
        power_w: float | None = None,
        current_density_a_per_m2: float | None = None,
        active: bool | None = None,
    ) -> None:
        """Change an electrode between steps (pose, drive, on/off); None keeps the current value."""
        names = [e.name for e in self.scene.electrodes]
        if name not in names:
            raise SceneError(
                f"unknown electrode {name!r}; electrodes: {', '.join(names) or 'none'}"
            )
        lx, ly, _ = self.scene.block_m
        if position_m is not None:
            x, y = (float(v) for v in position_m)
            if not (np.isfinite(x) and np.isfinite(y) and 0.0 <= x <= lx and 0.0 <= y <= ly):
                raise SceneError(
                    f"position_m: ({x}, {y}) lies off the top surface [0, {lx}] x [0, {ly}] m"
                )
            position_m = (x, y)
        for field_name, value in (
            ("power_w", power_w),
            ("current_density_a_per_m2", current_density_a_per_m2),
        ):
            if value is not None and not (np.isfinite(value) and value >= 0):
                raise SceneError(f"{field_name}: must be a finite number >= 0, got {value}")
        old = self.state.overrides.get(name, ElectrodeOverride())
        self.state.overrides[name] = ElectrodeOverride(
            position_m=position_m if position_m is not None else old.position_m,
            power_w=power_w
            if power_w is not None
            else (None if current_density_a_per_m2 is not None else old.power_w),
            current_density_a_per_m2=(
                current_density_a_per_m2
                if current_density_a_per_m2 is not None
                else (None if power_w is not None else old.current_density_a_per_m2)
            ),
            active=active if active is not None else old.active,
        )

    def run(self, n: int, callback: Callable[[StepReport], None] | None = None) -> list[StepReport]:
        """Advance n steps; the callback sees each report."""
        reports = []
        for _ in range(n):
            rep = self.step()
            reports.append(rep)
            if callback is not None:
                callback(rep)
        return reports

    # ------------------------------------------------------------------ the step
    def step(self) -> StepReport:
        """Advance one time step of the scene's dt; returns what ran, what it cost, key figures."""
        t_start = time.perf_counter()
        dt = self.scene.dt_s
        st = self.state
        rep = StepReport(step=st.step + 1, time_s=st.time_s + dt)
        t_mid = st.time_s + 0.5 * dt
        poses = [
            electrode_pose(el, t_mid, st.overrides.get(el.name)) for el in self.scene.electrodes
        ]
        T_old = st["temperature"].copy()
        self._rho_c_step = None
        for effect in self.effects:
            t0 = time.perf_counter()
            er = getattr(self, f"_step_{effect}")(poses, dt, rep, T_old)
            er.wall_s = time.perf_counter() - t0
            rep.effects[effect] = er
        st.step += 1
        st.time_s = st.step * dt  # no drift from summing dt
        self._finish_report(rep)
        rep.wall_s = time.perf_counter() - t_start
        self.last_report = rep
        return rep

    # --- electric
    def _conductivity(self) -> np.ndarray:
        st, t = self.state, self.tissue
        if "desiccation" in self.effects:
            sigma_n = electrical_conductivity(
                st["temperature"], st["vapor_fraction"], t, self.conductivity_law
            )
            sigma = nodes_to_tets(sigma_n, self.disc.mesh.tets)
        else:
            sigma = np.full(self.disc.n_tets, t.sigma_s_per_m)
        sigma[st["removed"]] = t.sigma_removed_s_per_m
        return sigma

    def _contact(self, pose: ElectrodePose) -> ContactWeights | None:
        """The contact disk of an electrode, on the healthy surface below it.

        None when the disk lies off the block, or when the cut under its centre reaches the
        bottom (the return electrode): no tissue is left between the electrodes.
        """
        x, y = pose.position_m
        z = self.top_z
        if "dissection" in self.effects and st_has_cut(self.state):
            g = self.grid
            # a centre just off an edge still touches with part of its disk: use the nearest column
            (x0, y0, z0), (lx, ly, _) = g.origin_m, g.size_m
            xc, yc = min(max(x, x0), x0 + lx), min(max(y, y0), y0 + ly)
            z = float(contact_height(self._contact_level_set(), g, xc, yc))
            # A front in the lower half of a cell layer leaves that layer's tets removed (half or
            # more cut): the disk goes down to the node layer under it, the top of the healthy
            # tets. Left in between, it loaded tets of sigma ~ 0 and the set power went into the
            # crater's vapor (R rose 100x and T passed 1100 K at dt 0.3 s).
            dz = g.spacing_m[2]
            k = np.floor((z - z0) / dz + 1e-9)
            if z - (z0 + k * dz) < REMOVED_FRACTION * dz:
                z = z0 + k * dz
            if z <= z0 + 1e-9 * dz:
                return None
        key = (x, y, z, pose.radius_m)
        if key not in self._contacts:
            try:
                self._contacts = {key: contact_weights(self.disc.mesh, (x, y, z), pose.radius_m)}
            except SceneError:
                return None
        return self._contacts[key]

    def _contact_level_set(self) -> np.ndarray:
        """phi (nz, ny, nx) in m as the electrode sees it: a loose fragment has fallen away.

        The level set still counts a fragment cut loose from the bottom as tissue (phi > 0), but
        its tets are removed; nodes with no healthy tet around them get phi < 0 here, so the
        contact drops to the healthy surface below instead of riding the fragment.
        """
        phi = self.state["level_set"]
        if self.topology is not None and self.topology.loose.any():
            tets = self.disc.mesh.tets[~self.state["removed"]]
            held = np.bincount(tets.ravel(), minlength=self.disc.n_nodes) > 0
            phi = np.where(held, phi, np.minimum(phi, -np.abs(phi) - 1e-12))
        return self.disc.to_grid(phi)

    def _step_electric(
        self, poses: list[ElectrodePose], dt: float, rep: StepReport, T_old: np.ndarray
    ) -> EffectReport:
        st = self.state
        active = [
            p
            for p in poses
            if p.active
            and (p.power_w > 0 if p.drive == "power" else p.current_density_a_per_m2 > 0)
        ]
        contacts = [(p, c) for p in active if (c := self._contact(p)) is not None]
        if not contacts:
            st["potential"] = np.zeros(self.disc.n_nodes)
            st["joule_heat"] = np.zeros(self.disc.n_tets)
            return EffectReport(
                False,
                "no active electrode in contact with the tissue (off the block, or cut through "
                "to the return electrode)",
            )
        contact, drive = _combined(contacts)
        sigma = self._conductivity()
        self.calls["electric"] += 1
        if self.scene.solver.coupling == "monolithic" and "thermal" in self.effects:
            self._monolithic = (sigma, contact, drive)
            return EffectReport(
                True, "solved with the temperature by block-preconditioned GMRES (monolithic)"
            )
        sol = self.potential.solve(sigma, contact, drive)
        st["potential"] = sol.V
        st["joule_heat"] = joule_heat(self.disc.geom.grads, self.disc.mesh.tets, sigma, sol.V)
        rep.delivered_power_w = sol.power_w
        if sol.stats.cached:
            return EffectReport(
                False,
                "conductivity and contact unchanged: potential reused (scaled to the drive)",
                extra={"current_a": sol.current_a},
            )
        return EffectReport(
            True,
            iterations=sol.stats.iterations,
            extra={
                "current_a": sol.current_a,
                "residual": sol.stats.residual,
                "reassembled": sol.stats.reassembled,
            },
        )

    # --- thermal
    def _step_thermal(
        self, poses: list[ElectrodePose], dt: float, rep: StepReport, T_old: np.ndarray
    ) -> EffectReport:
        st, t = self.state, self.tissue
        x = st["vapor_fraction"]
        rho_c = volumetric_heat_capacity(x, st["pressure"], T_old, t)
        k = nodes_to_tets(effective_conductivity(x, t), self.disc.mesh.tets)
        k[st["removed"]] = t.k_vapor_w_per_m_k
        q = st["joule_heat"]
        if not q.any() and np.all(T_old == self.heat.t_ambient_k):
            return EffectReport(False, "no heat source and the block is at ambient temperature")
        self.calls["thermal"] += 1
        if self._monolithic is not None:
            sigma, contact, drive = self._monolithic
            self._monolithic = None
            mono = self.coupled.monolithic_step(
                T_old,
                dt,
                sigma=sigma,
                contact=contact,
                drive=drive,
                rho_c=rho_c,
                k=k,
                rtol=self.scene.solver.thermal_rtol,
            )
            st["temperature"], st["potential"], st["joule_heat"] = mono.T, mono.V, mono.q
            rep.delivered_power_w = mono.power_w
            self._rho_c_step = rho_c
            self._add_heat_energy(mono.energy)
            return EffectReport(
                True,
                iterations=mono.heat.iterations,
                extra={"coupling": "monolithic", "picard_passes": mono.picard_passes},
            )
        res = self.heat.step(T_old, dt, rho_c=rho_c, k=k, q=q)
        st["temperature"] = res.T
        self._rho_c_step = rho_c
        self._add_heat_energy(res.energy)
        return EffectReport(
            True,
            iterations=res.stats.iterations,
            extra={
                "preconditioner": res.stats.preconditioner,
                "fallback_nodes": int(res.stats.fallback_nodes.size),
            },
        )

    def _add_heat_energy(self, energy: HeatEnergy) -> None:
        e = self.state.energy_j
        e["joule_in"] += energy.joule_j
        e["convective_out"] += energy.convective_loss_j
        e["sensible_stored"] += energy.stored_j

    # --- vaporization
    def _step_vaporization(
        self, poses: list[ElectrodePose], dt: float, rep: StepReport, T_old: np.ndarray
    ) -> EffectReport:
        st, t = self.state, self.tissue
        T_star, x_old = st["temperature"], st["vapor_fraction"]
        if not (T_star.max() > t.t_boil_k or x_old.any()):
            st["pressure"] = np.full(self.disc.n_nodes, t.p_atm_pa)
            return EffectReport(False, "no node above saturation: p = p0, no vapor")
        self.calls["vaporization"] += 1
        rho_c = self._rho_c_step
        if rho_c is None:
            rho_c = volumetric_heat_capacity(x_old, st["pressure"], T_old, t)
        eos = local_energy_balance(T_star, x_old, rho_c, t)
        vol = self.disc.node_volumes_m3
        # the latent heat moved out of the sensible store this step (exact split, see eos)
        latent_delta = float(
            np.dot(vol, water_mass_density(t) * t.latent_heat_j_per_kg * (eos.x - x_old))
        )
        st.energy_j["sensible_stored"] -= latent_delta
        st.energy_j["latent_stored"] += latent_delta
        st["temperature"], st["vapor_fraction"], st["pressure"] = eos.T, eos.x, eos.p
        return EffectReport(
            True, iterations=eos.iterations, extra={"vapor_nodes": int(np.count_nonzero(eos.x))}
        )

    # --- mechanics
    def _youngs(self) -> tuple[np.ndarray, np.ndarray]:
        t = self.tissue
        healthy = ~self.state["removed"]
        E = np.where(healthy, t.youngs_modulus_pa, t.ersatz_stiffness_ratio * t.youngs_modulus_pa)
        return E, healthy

    def _step_mechanics(
        self, poses: list[ElectrodePose], dt: float, rep: StepReport, T_old: np.ndarray
    ) -> EffectReport:
        st, t = self.state, self.tissue
        p = st["pressure"]
        if not np.any(p != t.p_atm_pa):
            st["displacement"] = np.zeros((self.disc.n_nodes, 3))
            st["strain_energy"] = np.zeros(self.disc.n_tets)
            self._last_mech_key = None
            return EffectReport(False, "pressure is p0 everywhere: u = 0, W = 0")
        E, healthy = self._youngs()
        key = (p.tobytes(), st["removed"].tobytes())
        if key == self._last_mech_key:
            return EffectReport(False, "pressure and topology unchanged: displacement reused")
        self.calls["mechanics"] += 1
        out = self.mechanics.solve(
            pressure_pa=p,
            level_set_m=st["level_set"],
            youngs_modulus_pa=E,
            healthy=healthy,
            warm_start=st["displacement"],
        )
        st["displacement"] = out.u
        E_eff = E.copy()
        if out.loose_tets is not None:
            E_eff[out.loose_tets] = t.ersatz_stiffness_ratio * t.youngs_modulus_pa
        st["strain_energy"] = strain_energy_density(
            self.disc.geom.grads, self.disc.mesh.tets, out.u, E_eff, t.poisson_ratio
        )
        self._last_mech_key = key
        return EffectReport(
            True,
            iterations=out.iterations,
            extra={
                "backend": self.mechanics.name,
                "rebuilt": out.rebuilt,
                "residual": out.residual,
                **out.extra,
            },
        )

    # --- dissection
    def _step_dissection(
        self, poses: list[ElectrodePose], dt: float, rep: StepReport, T_old: np.ndarray
    ) -> EffectReport:
        st, t = self.state, self.tissue
        kappa = t.damage_kappa_j_per_m3
        W = st["strain_energy"]
        if not W.max() > kappa:
            return EffectReport(
                False, "strain energy below kappa everywhere: the cut does not move"
            )
        self.calls["dissection"] += 1
        ls = self.scene.level_set
        if self._incidence is None:
            self._incidence = volume_incidence(
                self.disc.mesh.tets, self.disc.geom.volumes, self.disc.n_nodes
            )
        # removed tets carry ~0 W: leave them out so they don't dilute W on the cut surface
        W_nodes = tet_to_node(
            W,
            self.disc.mesh.tets,
            self.disc.geom.volumes,
            self.disc.n_nodes,
            include=~st["removed"],
            incidence=self._incidence,
        )
        F = front_speed(W_nodes, kappa, ls.v0_m_per_s)
        phi = self.disc.to_grid(st["level_set"])
        adv = advance(phi, F, self.grid.spacing_m, dt, cfl=ls.cfl)
        new_phi = adv.phi
        self._steps_since_reinit += 1
        reinit = self._steps_since_reinit >= ls.reinit_every
        if reinit:
            # keeps every node's sign and never raises phi next to the front (see reinitialize)
            new_phi = reinitialize(new_phi, self.grid.spacing_m)
            self._steps_since_reinit = 0
        st["level_set"] = new_phi.ravel()
        topo = evaluate_topology(
            st["level_set"], self.disc.mesh, self.disc.geom.volumes, self.topology
        )
        self.topology = topo
        removed = topo.removed | topo.loose
        changed = int(np.count_nonzero(removed != st["removed"]))
        st["removed"] = removed
        return EffectReport(
            True,
            iterations=adv.n_substeps,
            extra={
                "active_nodes": adv.n_active,
                "reinitialized": reinit,
                "tets_changed": changed,
                "loose_tets": int(topo.loose.sum()),
            },
        )

    # --- optional effects
    def _step_desiccation(
        self, poses: list[ElectrodePose], dt: float, rep: StepReport, T_old: np.ndarray
    ) -> EffectReport:
        return EffectReport(True, "applied in the conductivity of the next electric solve")

    def _step_thermal_damage(
        self, poses: list[ElectrodePose], dt: float, rep: StepReport, T_old: np.ndarray
    ) -> EffectReport:
        st = self.state
        self.calls["thermal_damage"] += 1
        st["thermal_damage"] = st["thermal_damage"] + arrhenius_damage_increment(
            T_old, st["temperature"], dt, self.damage_law
        )
        return EffectReport(True)

    def _finish_report(self, rep: StepReport) -> None:
        st = self.state
        rep.max_temperature_k = float(st["temperature"].max())
        rep.max_pressure_pa = float(st["pressure"].max())
        rep.max_displacement_m = float(np.linalg.norm(st["displacement"], axis=1).max())
        rep.max_strain_energy_j_per_m3 = float(st["strain_energy"].max())
        if self.topology is not None:
            rep.cut_volume_m3 = self.topology.cut_volume_m3
            rep.crater_depth_m = self.topology.crater_depth_m
        e = dict(st.energy_j)
        e["imbalance"] = (
            e["joule_in"] - e["convective_out"] - e["sensible_stored"] - e["latent_stored"]
        )
        rep.energy = e

    # ------------------------------------------------------------------ output and persistence
    def write_vtu(self, path: str | Path) -> Path:
        """The current state as a ParaView VTU file."""
        from diathermy.engine.vtu import write_vtu

        nodal = {
            n: v.reshape(self.disc.n_nodes, -1).squeeze() for n, v in self.nodal_fields().items()
        }
        cells = {k: v.astype(np.float64) for k, v in self.cell_fields().items()}
        return write_vtu(path, self.disc.mesh.points, self.disc.mesh.tets, nodal, cells)

    def solver_state(self) -> dict[str, np.ndarray]:
        """Solver data that decides the next iterates: the cached unit potential, warm starts."""
        out: dict[str, np.ndarray] = {}
        warm = self.potential.solver.krylov.warm_start
        if warm is not None:
            out["potential_warm_start"] = warm
        cached = self.potential.cached_unit_field()
        if cached is not None:
            contact, (V1, load1, R) = cached
            key = next((k for k, c in self._contacts.items() if c is contact), None)
            if key is not None:
                out["potential_unit_V"], out["potential_unit_load"] = V1, load1
                out["potential_unit_R"] = np.asarray(R)
                out["potential_contact_key"] = np.asarray(key)
                # the conductivity V1 was solved with: the cut may have changed it since
                out["potential_sigma"] = np.asarray(self.potential.solver.sigma)
        return out

    def restore_solver_state(
        self, solver: dict[str, np.ndarray], *, steps_since_reinit: int, mechanics_current: bool
    ) -> None:
        """Put back what ``solver_state`` saved, so the next step repeats the original run."""
        st = self.state
        self._steps_since_reinit = steps_since_reinit
        if "dissection" in self.effects and (st["removed"].any() or st.step > 0):
            self.topology = evaluate_topology(
                st["level_set"], self.disc.mesh, self.disc.geom.volumes
            )
        if mechanics_current:
            self._last_mech_key = (st["pressure"].tobytes(), st["removed"].tobytes())
        if "potential_warm_start" in solver:
            self.potential.solver.krylov.warm_start = solver["potential_warm_start"]
        if "potential_unit_V" in solver:
            x, y, z, r = (float(v) for v in solver["potential_contact_key"])
            contact = contact_weights(self.disc.mesh, (x, y, z), r)
            self._contacts = {(x, y, z, r): contact}
            sigma = solver.get("potential_sigma")
            self.potential.solver.set_conductivity(self._conductivity() if sigma is None else sigma)
            self.potential.restore_unit_field(
                contact,
                (
                    solver["potential_unit_V"],
                    solver["potential_unit_load"],
                    float(solver["potential_unit_R"]),
                ),
            )

    def write_cut_surface(self, path: str | Path) -> None:
        """The cut (phi = 0) as a triangle mesh file; the suffix picks the format (.vtu, .ply, .stl)."""
        write_cut_surface(path, cut_surface(self.disc.to_grid(self.state["level_set"]), self.grid))

    def save_checkpoint(self, path: str | Path) -> Path:
        from diathermy.engine.checkpoint import save_checkpoint

        return save_checkpoint(self, path)

    @classmethod
    def load_checkpoint(cls, path: str | Path) -> Simulation:
        from diathermy.engine.checkpoint import load_checkpoint

        return load_checkpoint(path)


def st_has_cut(state: SimulationState) -> bool:
    return bool(state["removed"].any())


def _combined(
    contacts: list[tuple[ElectrodePose, ContactWeights]],
) -> tuple[ContactWeights, ElectrodeDrive]:
    """Several active electrodes act as one generator output of equal current density."""
    if len(contacts) == 1:
        pose, c = contacts[0]
        return c, ElectrodeDrive(pose.drive, pose.current_density_a_per_m2, pose.power_w)  # type: ignore[arg-type]
    weights = sum(c.weights for _, c in contacts)
    area = sum(c.area_m2 for _, c in contacts)
    if all(p.drive == "power" for p, _ in contacts):
        drive = ElectrodeDrive("power", power_w=sum(p.power_w for p, _ in contacts))
    else:
        j = sum(p.current_density_a_per_m2 * c.area_m2 for p, c in contacts) / area
        drive = ElectrodeDrive("current_density", current_density_a_per_m2=j)
    return ContactWeights(weights=np.asarray(weights), area_m2=float(area)), drive


def make_backend(sim: Simulation) -> MechanicsBackend:
    """The backend the scene asks for."""
    cfg = sim.scene.mechanics
    if cfg.backend == "fem":
        return FEMBackend(
            sim.disc.mesh,
            poisson_ratio=sim.tissue.poisson_ratio,
            p0_pa=sim.tissue.p_atm_pa,
            rtol=cfg.rtol,
            ersatz_ratio=sim.tissue.ersatz_stiffness_ratio,
        )
    if cfg.backend == "cnn":
        # torch loads only here: an FEM-only engine never imports it
        from diathermy.surrogates.backend import CNNBackend, default_model_path

        return CNNBackend(
            sim.disc.mesh,
            _cnn_model_path(cfg.model, sim.scene.grid, default_model_path),
            poisson_ratio=sim.tissue.poisson_ratio,
            p0_pa=sim.tissue.p_atm_pa,
            ersatz_ratio=sim.tissue.ersatz_stiffness_ratio,
            guard_tolerance=cfg.guard_tolerance,
            correction=cfg.correction,
            patch_threshold=cfg.patch_threshold,
            patch_layers=cfg.patch_layers,
        )
    if cfg.backend == "pgd":
        return _pgd_backend(sim)
    raise SceneError(f"mechanics.backend: unknown backend {cfg.backend!r}")


def _cnn_model_path(
    model: str | None,
    grid: tuple[int, int, int],
    shipped: Callable[[tuple[int, int, int]], Path],
) -> Path:
    """A checkpoint file for ``mechanics.model``: an existing file path, else a registry name
    (``name`` or ``name:version``) in ``$DIATHERMY_DATA_DIR``; with none given, the grid's active
    registry model, else the shipped one. Raises ``SceneError`` naming ``mechanics.model``."""
    from diathermy.worker.registry import resolve_model

    if model is not None and Path(model).is_file():
        return Path(model)
    data_dir = Path(os.environ.get("DIATHERMY_DATA_DIR", "diathermy-data"))
    if model is None:
        active = resolve_model(data_dir, grid)
        return active if active is not None else shipped(grid)
    try:
        path = resolve_model(data_dir, grid, model)
    except SceneError as err:
        raise SceneError(
            f"mechanics.model: {model!r} is neither a file nor a model in the registry at "
            f"{data_dir} ({err})"
        ) from None
    if path is None or not Path(path).is_file():
        raise SceneError(f"mechanics.model: registry model {model!r} has no checkpoint file")
    return Path(path)


def _pgd_backend(sim: Simulation) -> MechanicsBackend:
    """Hybrid-PGD from ``scene.mechanics.model``; ``guard_tolerance`` turns on online enrichment."""
    from diathermy.surrogates.pgd.backend import PGDBackend
    from diathermy.surrogates.pgd.model import load_model

    cfg = sim.scene.mechanics
    if not cfg.model:
        raise SceneError(
            "mechanics.backend 'pgd' needs mechanics.model: a PGD model file (diathermy pgd-build)"
        )
    model = load_model(cfg.model, grid_shape=sim.scene.grid, block_m=sim.scene.block_m)

    def position() -> tuple[float, float] | None:
        t_mid = sim.state.time_s + 0.5 * sim.scene.dt_s  # the step's pose time (see step())
        for el in sim.scene.electrodes:
            pose = electrode_pose(el, t_mid, sim.state.overrides.get(el.name))
            if pose.active:
                return pose.position_m
        return None

    return PGDBackend(
        model,
        sim.disc.mesh,
        sim.disc.grid,
        enrich_tol=cfg.guard_tolerance,
        position_fn=position,
        rtol=cfg.rtol,
    )
