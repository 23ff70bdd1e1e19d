// Stream frames to pixels and readouts: the tissue's top layer (volume frames), the cut surface
// (surface frames), the legend's range, and the panel.
import { drawLegend, fillColours, range } from "./colour.js";
import { decodeArray } from "./wire.js";

const $ = (id) => document.getElementById(id);

export function onMessage(st, stats, setStatus, kind, msg, bytes) {
  stats.bytes += bytes;
  if (msg.type === "frame") {
    stats.framesReceived[kind] += 1;
    st.raw[kind] = msg;
    if (kind === "surface") {
      const now = performance.now();
      stats.stepsAt.push([now, msg.step]);
      while (stats.stepsAt.length > 2 && now - stats.stepsAt[0][0] > 3000) stats.stepsAt.shift();
    }
  } else if (msg.type === "error") {
    setStatus(`${msg.error}${msg.field ? ` (${msg.field})` : ""}: ${msg.message}`, true);
  } else if (msg.type === "ack" && msg.of === "run") {
    setStatus(`running at ${msg.rate_hz} steps/s`);
  } else if (msg.type === "ack" && msg.of === "pause") {
    setStatus("paused");
  }
}

// The top face's values: a "top" region frame carries (ny, nx[, 3]) already; a volume frame
// (nz, ny, nx[, 3]) is cut to its last z layer.
function topLayer(arr, comps) {
  if (arr.shape.length === (comps === 1 ? 2 : 3)) return arr.values;
  const [nz, ny, nx] = arr.shape;
  const n = ny * nx * comps;
  return arr.values.subarray((nz - 1) * n, nz * n);
}

export function applyFrames(st, view) {
  const colour = $("colour").value;
  const vol = st.last.volume;
  const surf = st.last.surface;
  const volCol = vol && vol.fields[colour] ? topLayer(decodeArray(vol.fields[colour]), 1) : null;
  const surfCol = surf && surf.fields[colour] ? decodeArray(surf.fields[colour]).values : null;
  const r = range(colour, [volCol, surfCol]);
  drawLegend($("legend-bar"), $("legend-labels"), r);
  if (vol && view.grid) {
    const g = view.grid;
    const colours = new Float32Array(3 * g.nx * g.ny).fill(0.6);
    if (volCol) fillColours(volCol, r, colours);
    const disp = vol.fields.displacement ? topLayer(decodeArray(vol.fields.displacement), 3) : null;
    const phi = vol.fields.level_set ? topLayer(decodeArray(vol.fields.level_set), 1) : null;
    view.updateTissue(colours, disp, phi, st.exaggeration);
  }
  if (surf && surf.surface && view.grid) {
    const verts = decodeArray(surf.surface.vertices).values;
    const faces = decodeArray(surf.surface.faces).values;
    const colours = new Float32Array(verts.length).fill(0.6);
    if (surfCol) fillColours(surfCol, r, colours);
    const disp = surf.fields.displacement ? decodeArray(surf.fields.displacement).values : null;
    view.updateCut(verts, faces, colours, disp, st.exaggeration);
  }
}

function fmt(v, digits, unit) {
  return v === null || v === undefined ? "-" : `${Number(v).toFixed(digits)} ${unit}`;
}

// How far the cut, the vapor and the lesion reach beyond a graded grid's fine working region
// (the step report's beyond_fine_region_m, m): "inside", or what left it and how far; a uniform
// grid has none.
export function fineRegionText(beyond) {
  if (!beyond || Object.keys(beyond).length === 0) return "uniform grid";
  const out = Object.entries(beyond).filter(([, v]) => v > 0);
  if (!out.length) return "inside";
  return out.map(([k, v]) => `${k} ${(1e3 * v).toFixed(1)} mm beyond`).join(", ");
}

// The effects the scene leaves out that would have acted this step (the step report's
// left_out_effects, name -> why): "none", or their names; the reasons go in the tooltip.
export function leftOutText(leftOut) {
  const names = Object.keys(leftOut || {});
  return names.length ? `${names.join(", ")} would act` : "none";
}

// The electrode's voltage from the step report's electric effect (V), and whether the
// generator's voltage limit held it there; "-" when the electric solve did not run.
export function voltageText(rep) {
  const extra = rep && rep.effects && rep.effects.electric ? rep.effects.electric.extra : null;
  if (!extra || extra.voltage_v === undefined) return "-";
  return `${Number(extra.voltage_v).toFixed(0)} V${extra.voltage_limited ? " (limited)" : ""}`;
}

export function updatePanel(st, stats) {
  const s = st.last.surface;
  if (!s) return;
  const rep = s.report;
  $("p-step").textContent = String(s.step);
  $("p-time").textContent = fmt(s.time_s, 2, "s");
  const h = stats.stepsAt;
  const rate = h.length > 1 ? (1000 * (h[h.length - 1][1] - h[0][1])) / (h[h.length - 1][0] - h[0][0] || 1) : 0;
  $("p-rate").textContent = rate.toFixed(1);
  $("p-power").textContent = rep ? fmt(rep.delivered_power_w, 1, "W") : "-";
  $("p-voltage").textContent = voltageText(rep);
  $("p-tmax").textContent = rep ? `${rep.max_temperature_k.toFixed(0)} K (${(rep.max_temperature_k - 273.15).toFixed(0)} °C)` : "-";
  $("p-depth").textContent = rep ? fmt(1e3 * rep.crater_depth_m, 2, "mm") : "-";
  $("p-cut").textContent = rep ? fmt(1e9 * rep.cut_volume_m3, 2, "mm³") : "-";
  const region = $("p-region");
  region.textContent = rep ? fineRegionText(rep.beyond_fine_region_m) : "-";
  region.className = region.textContent.includes("beyond") ? "warn" : "";
  const leftOut = $("p-left-out");
  leftOut.textContent = rep ? leftOutText(rep.left_out_effects) : "-";
  leftOut.title = rep ? Object.values(rep.left_out_effects || {}).join("; ") : "";
  leftOut.className = leftOut.textContent.endsWith("would act") ? "warn" : "";
  const dropped = st.streams ? st.streams.surface.totalDropped + st.streams.volume.totalDropped : 0;
  $("p-dropped").textContent = String(dropped);
}

export function drawFps(stats) {
  const now = performance.now();
  while (stats.drawnAt.length && now - stats.drawnAt[0] > 2000) stats.drawnAt.shift();
  return stats.drawnAt.length / 2;
}
