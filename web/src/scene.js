// The WebGL part of the viewer (three.js): one canvas, one camera, and one or two views of a
// cloud side by side (split viewports), colored in the shader from a per-point value through
// a lookup table, so new color limits cost a uniform update, not a pass over the points.
import {
  BufferAttribute, BufferGeometry, DataTexture, Group, Matrix4, NearestFilter,
  PerspectiveCamera, Points, PointsMaterial, Quaternion, RGBAFormat, Scene, ShaderMaterial,
  UnsignedByteType, Vector3, WebGLRenderer,
} from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
import { LUT_SIZE, NAN_COLOR } from "./colormaps.js";

// Decimation rule: while the camera moves, at most MOVING_BUDGET points are drawn (in all
// views together): the first ones of a fixed random order, so a uniform sample of the cloud.
// Every point is drawn again IDLE_MS after the last movement.
export const MOVING_BUDGET = 300000;
export const IDLE_MS = 200;
const NO_VALUE = 3.0e38;  // NaN stand-in in the value attribute: above every float32 value
const SEED = 12345;

const VERTEX = `
attribute float value;
uniform float vmin;
uniform float vmax;
uniform float diverging;
uniform float pointSize;
varying float vT;
void main() {
  gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
  gl_PointSize = pointSize;
  if (value > 1.0e38) { vT = -1.0; return; }
  float t = diverging > 0.5
    ? (value < 0.0 ? 0.5 - 0.5 * value / vmin : 0.5 + 0.5 * value / vmax)
    : (value - vmin) / (vmax - vmin);
  vT = clamp(t, 0.0, 1.0);
}`;
const FRAGMENT = `
uniform sampler2D lut;
uniform float lutSize;
uniform float categorical;
uniform vec3 nanColor;
varying float vT;
void main() {
  if (vT < 0.0) { gl_FragColor = vec4(nanColor, 1.0); return; }
  float u = categorical > 0.5 ? vT : (vT * (lutSize - 1.0) + 0.5) / lutSize;
  gl_FragColor = vec4(texture2D(lut, vec2(u, 0.5)).rgb, 1.0);
}`;

/** A fixed pseudo-random permutation of 0..n-1 (xorshift32 + Fisher-Yates). */
export function randomOrder(n, seed = SEED) {
  const order = new Uint32Array(n);
  for (let i = 0; i < n; i++) order[i] = i;
  let state = seed >>> 0 || 1;
  for (let i = n - 1; i > 0; i--) {
    state ^= state << 13; state >>>= 0;
    state ^= state >>> 17;
    state ^= state << 5; state >>>= 0;
    const j = state % (i + 1);
    const tmp = order[i]; order[i] = order[j]; order[j] = tmp;
  }
  return order;
}

function gather(source, order, width) {
  const out = new Float32Array(order.length * width);
  for (let i = 0; i < order.length; i++) {
    const k = order[i] * width;
    for (let c = 0; c < width; c++) out[i * width + c] = source[k + c];
  }
  return out;
}

/** Rotation taking the world frame (right, forward, up) of `up` to three.js's (x, -z, y),
 * the same frame as curvature.preview.world_frame, so "front" looks along forward. */
export function upRotation(up) {
  const u = new Vector3(...up).normalize();
  const seed = Math.abs(u.x) < 0.9 ? new Vector3(1, 0, 0) : new Vector3(0, 1, 0);
  const right = seed.clone().addScaledVector(u, -seed.dot(u)).normalize();
  const forward = new Vector3().crossVectors(u, right);
  // Rows right, up, -forward: a world vector's coordinates in three.js's x, y, z.
  const m = new Matrix4().set(
    right.x, right.y, right.z, 0,
    u.x, u.y, u.z, 0,
    -forward.x, -forward.y, -forward.z, 0,
    0, 0, 0, 1);
  return new Quaternion().setFromRotationMatrix(m);
}

class View {
  constructor() {
    this.scene = new Scene();
    this.group = new Group();
    this.scene.add(this.group);
    this.material = new ShaderMaterial({
      vertexShader: VERTEX, fragmentShader: FRAGMENT,
      uniforms: {
        vmin: { value: -1 }, vmax: { value: 1 }, diverging: { value: 1 },
        pointSize: { value: 2 }, lut: { value: null }, lutSize: { value: LUT_SIZE },
        categorical: { value: 0 },
        nanColor: { value: NAN_COLOR.map((c) => c / 255) },
      },
    });
    this.geometry = new BufferGeometry();
    this.points = new Points(this.geometry, this.material);
    this.points.frustumCulled = false;
    this.group.add(this.points);
    this.marker = new Points(new BufferGeometry(), new PointsMaterial({
      color: 0x000000, size: 11, sizeAttenuation: false, depthTest: false }));
    this.marker.renderOrder = 1;
    this.marker.visible = false;
    this.group.add(this.marker);
    this.order = null;  // drawn slot -> point index
    this.positions = null;  // original order, Float32Array (3n)
    this.n = 0;
  }
}

export class PointScene {
  /** @param {HTMLCanvasElement} canvas */
  constructor(canvas) {
    this.canvas = canvas;
    this.renderer = new WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.renderer.setClearColor(0xffffff, 1);
    this.renderer.setScissorTest(true);
    this.camera = new PerspectiveCamera(40, 1, 1e-3, 1e3);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.addEventListener("change", () => this.moved());
    this.views = [new View()];
    this.pointSize = 2;
    this.budget = MOVING_BUDGET;
    this.moving = false;
    this.idleTimer = null;
    this.frameRequested = false;
    this.lastFrameMs = 0;
    this.lastDrawn = 0;
    this.radius = 1;
    this.quaternion = new Quaternion();
    new ResizeObserver(() => this.resize()).observe(canvas);
    this.resize();
  }

  /** Number of views side by side (1 or 2). */
  setViewCount(count) {
    while (this.views.length < count) {
      const view = new View();
      view.group.quaternion.copy(this.quaternion);
      this.views.push(view);
    }
    while (this.views.length > count) {
      const view = this.views.pop();
      view.geometry.dispose();
      view.material.dispose();
    }
    this.resize();
  }

  /**
   * The cloud of a view.
   * @param {number} v view index
   * @param {Float32Array} positions (3n) x y z per point
   * @param {View} [shareWith] a view of the same cloud whose buffers are reused
   */
  setCloud(v, positions, shareWith = null) {
    const view = this.views[v];
    view.n = positions.length / 3;
    view.positions = positions;
    if (shareWith && shareWith.n === view.n) {
      view.order = shareWith.order;
      view.geometry.setAttribute("position", shareWith.geometry.getAttribute("position"));
    } else {
      view.order = randomOrder(view.n);
      view.geometry.setAttribute("position",
        new BufferAttribute(gather(positions, view.order, 3), 3));
    }
    view.geometry.setAttribute("value", new BufferAttribute(new Float32Array(view.n), 1));
    view.marker.visible = false;
    this.frame();
  }

  /** The values (n, in point order; NaN: no value) that color view v. */
  setValues(v, values) {
    const view = this.views[v];
    const attribute = view.geometry.getAttribute("value");
    const out = attribute.array;
    for (let i = 0; i < view.n; i++) {
      const x = values[view.order[i]];
      out[i] = Number.isFinite(x) ? x : NO_VALUE;
    }
    attribute.needsUpdate = true;
    this.requestRender();
  }

  /** Color limits and map of every view: mode diverging | sequential | categorical. */
  setColoring(vmin, vmax, mode, lut) {
    const texture = new DataTexture(lut, lut.length / 4, 1, RGBAFormat, UnsignedByteType);
    texture.magFilter = NearestFilter;
    texture.minFilter = NearestFilter;
    texture.needsUpdate = true;
    for (const view of this.views) {
      const u = view.material.uniforms;
      if (u.lut.value) u.lut.value.dispose();
      u.lut.value = texture;
      u.lutSize.value = lut.length / 4;
      u.vmin.value = vmin;
      u.vmax.value = vmax > vmin ? vmax : vmin + 1e-30;
      u.diverging.value = mode === "diverging" && vmin < 0 && vmax > 0 ? 1 : 0;
      u.categorical.value = mode === "categorical" ? 1 : 0;
    }
    this.requestRender();
  }

  setPointSize(size) {
    this.pointSize = size;
    this.requestRender();
  }

  /** Set the world's up direction and look at the cloud from the iso preset. */
  setUp(up) {
    this.quaternion = upRotation(up);
    for (const view of this.views) view.group.quaternion.copy(this.quaternion);
    this.frame();
  }

  /** Camera on the iso preset (from right, front and above), the whole first cloud in view. */
  frame() {
    const view = this.views[0];
    if (!view.positions || !view.n) { this.requestRender(); return; }
    const p = view.positions;
    const lo = [Infinity, Infinity, Infinity];
    const hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < p.length; i += 3) {
      for (let c = 0; c < 3; c++) {
        if (p[i + c] < lo[c]) lo[c] = p[i + c];
        if (p[i + c] > hi[c]) hi[c] = p[i + c];
      }
    }
    const centre = new Vector3((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2);
    this.radius = Math.max(0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]),
      1e-9);
    for (const v of this.views) v.group.updateMatrixWorld(true);
    const target = centre.applyQuaternion(this.quaternion);
    const half = (this.camera.fov * Math.PI) / 360;  // vertical; the narrower one fits
    const narrow = Math.min(half, Math.atan(Math.tan(half) * this.camera.aspect));
    const distance = (this.radius / Math.sin(narrow)) * 1.02;
    const eye = new Vector3(1, 1, 1).normalize().multiplyScalar(distance).add(target);
    this.camera.near = distance / 100;
    this.camera.far = distance * 100;
    this.camera.position.copy(eye);
    this.camera.up.set(0, 1, 0);
    this.controls.target.copy(target);
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.requestRender();
  }

  resize() {
    const width = this.canvas.clientWidth || 1;
    const height = this.canvas.clientHeight || 1;
    this.renderer.setSize(width, height, false);
    this.camera.aspect = width / this.views.length / height;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }

  moved() {
    this.moving = true;
    clearTimeout(this.idleTimer);
    this.idleTimer = setTimeout(() => { this.moving = false; this.requestRender(); }, IDLE_MS);
    this.requestRender();
  }

  requestRender() {
    if (this.frameRequested) return;
    this.frameRequested = true;
    requestAnimationFrame(() => { this.frameRequested = false; this.render(); });
  }

  /** Draw every view; `moving` (default: the camera is moving) limits the points drawn. */
  render(moving = this.moving) {
    const start = performance.now();
    const width = this.canvas.clientWidth / this.views.length;  // CSS pixels, as three.js
    const height = this.canvas.clientHeight;
    const share = Math.floor(this.budget / this.views.length);
    let drawn = 0;
    this.views.forEach((view, k) => {
      const count = moving ? Math.min(view.n, share) : view.n;
      view.geometry.setDrawRange(0, count);
      view.material.uniforms.pointSize.value = this.pointSize * this.renderer.getPixelRatio();
      drawn += count;
      this.renderer.setViewport(k * width, 0, width, height);
      this.renderer.setScissor(k * width, 0, width, height);
      this.renderer.render(view.scene, this.camera);
    });
    this.lastDrawn = drawn;
    this.lastFrameMs = performance.now() - start;
    if (this.onrender) this.onrender({ drawn, moving });
  }

  /** Milliseconds of `frames` frames (each waited for by reading a pixel back) while the
   * camera turns around the cloud, drawing every point or (moving) the decimated set. */
  measure(frames, moving) {
    const gl = this.renderer.getContext();
    const pixel = new Uint8Array(4);
    const times = [];
    for (let i = 0; i < frames; i++) {
      const start = performance.now();
      this.rotate(360 / frames, 0);
      this.render(moving);
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);
      times.push(performance.now() - start);
    }
    return times;
  }

  /** Turn the camera around the target by azimuth and elevation (degrees). */
  rotate(azimuth, elevation) {
    const offset = this.camera.position.clone().sub(this.controls.target);
    offset.applyAxisAngle(new Vector3(0, 1, 0), (azimuth * Math.PI) / 180);
    const side = new Vector3().crossVectors(this.camera.up, offset).normalize();
    offset.applyAxisAngle(side, (elevation * Math.PI) / 180);
    this.camera.position.copy(this.controls.target).add(offset);
    this.camera.lookAt(this.controls.target);
    this.camera.updateMatrixWorld();
  }

  /** Which view a canvas x (CSS pixels) falls in, and that viewport's left edge and width. */
  viewAt(x) {
    const width = this.canvas.clientWidth / this.views.length;
    const k = Math.min(this.views.length - 1, Math.max(0, Math.floor(x / width)));
    return { k, left: k * width, width };
  }

  _matrix(view) {
    this.camera.updateMatrixWorld();
    view.group.updateMatrixWorld(true);
    return new Matrix4().multiplyMatrices(this.camera.projectionMatrix,
      this.camera.matrixWorldInverse).multiply(view.group.matrixWorld).elements;
  }

  /**
   * The point drawn at a canvas position (CSS pixels from the canvas's top left): among the
   * points projecting within a few pixels, the nearest to the camera.
   * @returns {{view: number, index: number} | null}
   */
  pick(x, y) {
    const { k, left, width } = this.viewAt(x);
    const view = this.views[k];
    if (!view.n) return null;
    const height = this.canvas.clientHeight;
    const e = this._matrix(view);
    const p = view.positions;
    const r = Math.max(4, this.pointSize);
    const r2 = r * r;
    const lx = x - left;
    let best = -1;
    let bestDepth = Infinity;
    for (let i = 0; i < view.n; i++) {
      const px = p[3 * i]; const py = p[3 * i + 1]; const pz = p[3 * i + 2];
      const w = e[3] * px + e[7] * py + e[11] * pz + e[15];
      if (w <= 0) continue;
      const sx = ((e[0] * px + e[4] * py + e[8] * pz + e[12]) / w * 0.5 + 0.5) * width;
      const sy = (0.5 - (e[1] * px + e[5] * py + e[9] * pz + e[13]) / w * 0.5) * height;
      const dx = sx - lx; const dy = sy - y;
      if (dx * dx + dy * dy > r2) continue;
      const depth = (e[2] * px + e[6] * py + e[10] * pz + e[14]) / w;
      if (depth < bestDepth) { bestDepth = depth; best = i; }
    }
    return best < 0 ? null : { view: k, index: best };
  }

  /** Canvas position (CSS pixels) of point `index` in view `v`, or null behind the camera. */
  screenPosition(v, index) {
    const view = this.views[v];
    const e = this._matrix(view);
    const p = view.positions;
    const [px, py, pz] = [p[3 * index], p[3 * index + 1], p[3 * index + 2]];
    const w = e[3] * px + e[7] * py + e[11] * pz + e[15];
    if (w <= 0) return null;
    const width = this.canvas.clientWidth / this.views.length;
    return {
      x: v * width + ((e[0] * px + e[4] * py + e[8] * pz + e[12]) / w * 0.5 + 0.5) * width,
      y: (0.5 - (e[1] * px + e[5] * py + e[9] * pz + e[13]) / w * 0.5) *
        this.canvas.clientHeight,
    };
  }

  /** Show the marker on point `index` in every view of the same size (null: hide it). */
  mark(index) {
    for (const view of this.views) {
      if (index === null || index >= view.n) { view.marker.visible = false; continue; }
      const p = view.positions;
      view.marker.geometry.setAttribute("position", new BufferAttribute(
        new Float32Array([p[3 * index], p[3 * index + 1], p[3 * index + 2]]), 3));
      view.marker.visible = true;
    }
    this.requestRender();
  }
}
