// Colour maps, value ranges and the legend of the three display quantities.

// A perceptual dark-to-bright map (stops sampled by eye from "inferno"-like ramps), t in [0, 1].
const STOPS = [
  [0.0, [0.05, 0.03, 0.20]],
  [0.25, [0.38, 0.07, 0.43]],
  [0.5, [0.74, 0.21, 0.33]],
  [0.75, [0.98, 0.55, 0.10]],
  [1.0, [0.99, 0.99, 0.64]],
];

export function colourAt(t, out, offset) {
  const x = t > 0 ? (t < 1 ? t : 1) : 0;
  let i = 1;
  while (i < STOPS.length - 1 && STOPS[i][0] < x) i++;
  const [t0, c0] = STOPS[i - 1];
  const [t1, c1] = STOPS[i];
  const f = (x - t0) / (t1 - t0);
  out[offset] = c0[0] + f * (c1[0] - c0[0]);
  out[offset + 1] = c0[1] + f * (c1[1] - c0[1]);
  out[offset + 2] = c0[2] + f * (c1[2] - c0[2]);
}

// How each field is shown: display value from the raw value, unit, and the range's floor.
export const QUANTITIES = {
  temperature: {
    label: "temperature", unit: "°C",
    show: (k) => k - 273.15, min: () => 25, max: (hi) => Math.max(hi, 100),
  },
  pressure: {
    label: "pressure", unit: "MPa",
    show: (pa) => pa / 1e6, min: () => 0.1, max: (hi) => Math.max(hi, 0.2),
  },
  thermal_damage: {
    label: "damaged fraction 1 - e^-Ω", unit: "",
    show: (omega) => 1 - Math.exp(-omega), min: () => 0, max: () => 1,
  },
};

// The top of the colour range: the 98th percentile of the shown values (a few hot nodes at the
// electrode would otherwise leave everything else at the bottom of the map) and the true maximum.
export function upperShown(quantity, arrays) {
  const shown = [];
  for (const a of arrays) {
    if (!a) continue;
    for (let i = 0; i < a.length; i++) {
      const v = quantity.show(a[i]);
      if (Number.isFinite(v)) shown.push(v);
    }
  }
  if (shown.length === 0) return { p98: -Infinity, max: -Infinity };
  const sorted = Float64Array.from(shown).sort();
  return { p98: sorted[Math.floor(0.98 * (sorted.length - 1))], max: sorted[sorted.length - 1] };
}

export function range(name, arrays) {
  const q = QUANTITIES[name];
  const { p98, max } = upperShown(q, arrays);
  const hi = q.max(p98);
  return { q, lo: q.min(), hi, clipped: max > hi };
}

export function fillColours(values, r, out) {
  const span = r.hi - r.lo || 1;
  for (let i = 0; i < values.length; i++) {
    colourAt((r.q.show(values[i]) - r.lo) / span, out, 3 * i);
  }
}

function fmt(v) {
  const a = Math.abs(v);
  if (a >= 100) return v.toFixed(0);
  if (a >= 1) return v.toFixed(1);
  return v.toFixed(2);
}

export function drawLegend(canvas, labels, r) {
  const ctx = canvas.getContext("2d");
  const rgb = [0, 0, 0];
  for (let y = 0; y < canvas.height; y++) {
    colourAt(1 - y / (canvas.height - 1), rgb, 0);
    ctx.fillStyle = `rgb(${rgb.map((c) => Math.round(255 * c)).join(",")})`;
    ctx.fillRect(0, y, canvas.width, 1);
  }
  const unit = r.q.unit ? ` ${r.q.unit}` : "";
  const mid = 0.5 * (r.lo + r.hi);
  labels.innerHTML = "";
  for (const [text, cls] of [[`${r.clipped ? "≥ " : ""}${fmt(r.hi)}${unit}`, "hi"], [`${r.q.label}`, "name"], [`${fmt(mid)}`, "mid"], [`${fmt(r.lo)}${unit}`, "lo"]]) {
    const div = document.createElement("div");
    div.className = cls;
    div.textContent = text;
    labels.appendChild(div);
  }
}
