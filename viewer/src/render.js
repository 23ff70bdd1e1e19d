// The three.js view: the tissue's top surface, the cut surface (phi = 0), the electrode pin.
// Coordinates are the simulation's (x, y, z) in m, z up; one group scales the block to ~1 unit.
import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { tissueMesh } from "./tissue.js";

export class View {
  constructor(canvas) {
    this.canvas = canvas;
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(window.devicePixelRatio || 1);
    this.renderer.setClearColor(0x1b1e23);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(35, 1, 0.01, 100);
    this.camera.up.set(0, 0, 1);
    this.camera.position.set(0.0, -1.35, 1.05);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.target.set(0, 0, 0);
    this.controls.update();
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x404050, 1.6));
    const sun = new THREE.DirectionalLight(0xffffff, 1.4);
    sun.position.set(-0.6, -1.0, 2.0);
    this.scene.add(sun);
    this.group = new THREE.Group();
    this.scene.add(this.group);
    this.grid = null;
    this.tissue = null;
    this.cut = null;
    this.pin = null;
    this.dirty = true;
    this.controls.addEventListener("change", () => { this.dirty = true; });
    this.resize();
    window.addEventListener("resize", () => this.resize());
  }

  resize() {
    const w = this.canvas.clientWidth || 1;
    const h = this.canvas.clientHeight || 1;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.dirty = true;
  }

  clear() {
    for (const child of [...this.group.children]) {
      this.group.remove(child);
      child.traverse((o) => {
        if (o.geometry) o.geometry.dispose();
        if (o.material) o.material.dispose();
      });
    }
    this.grid = this.tissue = this.cut = this.pin = null;
    this.dirty = true;
  }

  // grid: the session's GridPublic (shape (nz, ny, nx), spacing_m or, graded, axes_m, origin_m, size_m)
  setGrid(grid, electrodeRadiusM) {
    this.clear();
    const [nz, ny, nx] = grid.shape;
    const [x0, y0, z0] = grid.origin_m;
    const [lx, ly, lz] = grid.size_m;
    const L = Math.max(lx, ly, lz);
    // node x and y coordinates: the graded grid's axes_m, or origin + index * spacing
    const xs = grid.axes_m ? grid.axes_m[0] : Array.from({ length: nx }, (_, i) => x0 + i * grid.spacing_m[0]);
    const ys = grid.axes_m ? grid.axes_m[1] : Array.from({ length: ny }, (_, j) => y0 + j * grid.spacing_m[1]);
    this.grid = { nx, ny, nz, x0, y0, z0, lx, ly, lz, xs, ys, top: z0 + lz, L };
    this.group.scale.setScalar(1 / L);
    this.group.position.set(-(x0 + lx / 2) / L, -(y0 + ly / 2) / L, -(z0 + lz / 2) / L);

    const box = new THREE.LineSegments(
      new THREE.EdgesGeometry(new THREE.BoxGeometry(lx, ly, lz)),
      new THREE.LineBasicMaterial({ color: 0x6c7686 }),
    );
    box.position.set(x0 + lx / 2, y0 + ly / 2, z0 + lz / 2);
    this.group.add(box);

    this.tissue = new THREE.Mesh(new THREE.BufferGeometry(), new THREE.MeshLambertMaterial({ vertexColors: true, side: THREE.DoubleSide }));
    this.group.add(this.tissue);
    this.updateTissue(new Float32Array(3 * nx * ny).fill(0.6), null, null, 1);

    const cutGeom = new THREE.BufferGeometry();
    this.cut = new THREE.Mesh(cutGeom, new THREE.MeshLambertMaterial({ vertexColors: true, side: THREE.DoubleSide }));
    this.group.add(this.cut);
    this.cutFaces = 0;

    const r = Math.max(electrodeRadiusM || 0, 0.012 * L);
    this.pinRadius = r;
    const pin = new THREE.Group();
    const metal = new THREE.MeshLambertMaterial({ color: 0x9fd3ff, emissive: 0x123040 });
    const ball = new THREE.Mesh(new THREE.SphereGeometry(r, 24, 16), metal);
    ball.position.z = r;
    const shaft = new THREE.Mesh(new THREE.CylinderGeometry(0.35 * r, 0.35 * r, 0.18 * L, 12), metal);
    shaft.rotation.x = Math.PI / 2;
    shaft.position.z = r + 0.09 * L;
    // a larger invisible target so the pin is easy to grab
    const grab = new THREE.Mesh(new THREE.SphereGeometry(3 * r, 12, 8), new THREE.MeshBasicMaterial({ visible: false }));
    grab.position.z = r;
    pin.add(ball, shaft, grab);
    this.pin = pin;
    this.pinMaterial = metal;
    this.group.add(pin);
    this.dirty = true;
  }

  // the top layer of volume fields: colours (3 per node), displacement (3 per node, m) and the
  // level set (m; null: nothing removed)
  updateTissue(colours, disp, phi, exaggeration) {
    if (!this.tissue) return;
    const mesh = tissueMesh(this.grid, colours, disp, phi, exaggeration);
    const geom = new THREE.BufferGeometry();
    geom.setAttribute("position", new THREE.BufferAttribute(mesh.positions, 3));
    geom.setAttribute("color", new THREE.BufferAttribute(mesh.colours, 3));
    geom.setIndex(new THREE.BufferAttribute(mesh.index, 1));
    geom.computeVertexNormals();
    this.tissue.geometry.dispose();
    this.tissue.geometry = geom;
    this.dirty = true;
  }

  // the cut surface of a surface frame: vertices (n*3, m), faces (m*3), colours, displacement
  updateCut(vertices, faces, colours, disp, exaggeration) {
    if (!this.cut) return;
    const pos = new Float32Array(vertices.length);
    for (let k = 0; k < vertices.length; k++) pos[k] = vertices[k] + (disp ? exaggeration * disp[k] : 0);
    const geom = new THREE.BufferGeometry();
    geom.setAttribute("position", new THREE.BufferAttribute(pos, 3));
    geom.setAttribute("color", new THREE.BufferAttribute(colours, 3));
    geom.setIndex(new THREE.BufferAttribute(Uint32Array.from(faces), 1));
    geom.computeVertexNormals();
    this.cut.geometry.dispose();
    this.cut.geometry = geom;
    this.cutFaces = faces.length / 3;
    this.dirty = true;
  }

  setElectrode(x, y, active) {
    if (!this.pin) return;
    this.pin.position.set(x, y, this.grid.top);
    this.pinMaterial.color.set(active ? 0x9fd3ff : 0x5d6470);
    this.pinMaterial.emissive.set(active ? 0x123040 : 0x000000);
    this.dirty = true;
  }

  _ray(clientX, clientY) {
    const rect = this.canvas.getBoundingClientRect();
    const ndc = new THREE.Vector2(((clientX - rect.left) / rect.width) * 2 - 1, -((clientY - rect.top) / rect.height) * 2 + 1);
    const ray = new THREE.Raycaster();
    ray.setFromCamera(ndc, this.camera);
    return ray;
  }

  hitsElectrode(clientX, clientY) {
    if (!this.pin) return false;
    return this._ray(clientX, clientY).intersectObject(this.pin, true).length > 0;
  }

  // (x, y) in m where the pointer ray meets the top plane, clamped to the block; null if none
  topPoint(clientX, clientY) {
    if (!this.grid) return null;
    const g = this.grid;
    this.group.updateMatrixWorld();
    const origin = new THREE.Vector3(0, 0, g.top).applyMatrix4(this.group.matrixWorld);
    const plane = new THREE.Plane(new THREE.Vector3(0, 0, 1), -origin.z);
    const hit = new THREE.Vector3();
    if (!this._ray(clientX, clientY).ray.intersectPlane(plane, hit)) return null;
    const local = this.group.worldToLocal(hit);
    const clamp = (v, lo, hi) => Math.min(hi, Math.max(lo, v));
    return [clamp(local.x, g.x0, g.x0 + g.lx), clamp(local.y, g.y0, g.y0 + g.ly)];
  }

  // page (CSS pixel) coordinates of a point on the top surface, for tests and tools
  screenOf(x, y) {
    const rect = this.canvas.getBoundingClientRect();
    this.group.updateMatrixWorld();
    const v = new THREE.Vector3(x, y, this.grid.top).applyMatrix4(this.group.matrixWorld).project(this.camera);
    return { x: rect.left + ((v.x + 1) / 2) * rect.width, y: rect.top + ((1 - v.y) / 2) * rect.height };
  }

  // point the camera at (x, y) on the top surface from ``distance`` (scene units; 1 = block size)
  look(x, y, distance) {
    if (!this.grid) return;
    this.group.updateMatrixWorld();
    const target = new THREE.Vector3(x, y, this.grid.top).applyMatrix4(this.group.matrixWorld);
    const dir = new THREE.Vector3(0, -1.35, 1.05).normalize().multiplyScalar(distance);
    this.controls.target.copy(target);
    this.camera.position.copy(target).add(dir);
    this.controls.update();
    this.dirty = true;
  }

  overview() {
    this.controls.target.set(0, 0, 0);
    this.camera.position.set(0.0, -1.35, 1.05);
    this.controls.update();
    this.dirty = true;
  }

  render() {
    this.renderer.render(this.scene, this.camera);
    this.dirty = false;
  }
}
