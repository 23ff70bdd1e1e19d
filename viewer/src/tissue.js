// The tissue's top surface as triangles: two per grid cell, clipped to the healthy side phi >= 0
// of the top layer's level set, so the opening meets the cut surface (phi = 0) where it crosses
// the grid edges instead of leaving whole cells open around the crater.

// g: the view's grid; colours (3 per node); disp (3 per node, m) or null; phi (1 per node, m) or
// null (nothing removed). Returns {positions, colours, index} for a BufferGeometry.
export function tissueMesh(g, colours, disp, phi, exaggeration) {
  const n = g.nx * g.ny;
  const pos = [];
  const col = Array.from(colours);
  for (let j = 0; j < g.ny; j++) {
    for (let i = 0; i < g.nx; i++) {
      const p = 3 * (j * g.nx + i);
      const e = disp ? exaggeration : 0;
      pos.push(
        g.xs[i] + (disp ? e * disp[p] : 0),
        g.ys[j] + (disp ? e * disp[p + 1] : 0),
        g.top + (disp ? e * disp[p + 2] : 0),
      );
    }
  }
  const crossings = new Map();
  const cross = (a, b) => {
    // the point on edge a-b (one healthy end, one removed) where phi is 0, made once per edge
    const key = a < b ? a * n + b : b * n + a;
    let v = crossings.get(key);
    if (v === undefined) {
      const t = phi[a] / (phi[a] - phi[b]);
      for (let k = 0; k < 3; k++) {
        pos.push(pos[3 * a + k] + t * (pos[3 * b + k] - pos[3 * a + k]));
        col.push(col[3 * a + k] + t * (col[3 * b + k] - col[3 * a + k]));
      }
      v = pos.length / 3 - 1;
      crossings.set(key, v);
    }
    return v;
  };
  const index = [];
  const triangle = (a, b, c) => {
    if (!phi) return index.push(a, b, c);
    const t = [a, b, c];
    const inside = t.map((v) => phi[v] >= 0);
    const count = inside.filter(Boolean).length;
    if (count === 3) return index.push(a, b, c);
    if (count === 0) return 0;
    // rotate (keeping the winding) so the vertex on its own side comes first
    const lone = count === 1 ? inside.indexOf(true) : inside.indexOf(false);
    const [p, q, r] = [t[lone], t[(lone + 1) % 3], t[(lone + 2) % 3]];
    if (count === 1) return index.push(p, cross(p, q), cross(p, r));
    const cq = cross(r, p);
    const cp = cross(p, q);
    return index.push(q, r, cq, q, cq, cp);
  };
  for (let j = 0; j < g.ny - 1; j++) {
    for (let i = 0; i < g.nx - 1; i++) {
      const a = j * g.nx + i, b = a + 1, c = a + g.nx, d = c + 1;
      triangle(a, b, d);
      triangle(a, d, c);
    }
  }
  return { positions: new Float32Array(pos), colours: new Float32Array(col), index: new Uint32Array(index) };
}
