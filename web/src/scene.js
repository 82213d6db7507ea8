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

// Decimation rule (progressive refinement): the points are stored in a fixed random order and
// each frame draws the next `chunk` of them (all views together) over the previous frame's
// picture, so every frame is a uniform sample of the cloud and the picture fills in until
// every point is drawn. A change of camera, colors or size starts again from the first chunk.
// The chunk adapts so that a frame takes about FRAME_MS (rAF intervals while drawing): the
// whole cloud per frame where the GPU allows it, a sample while turning where it does not.
export const FRAME_MS = 30;
export const MIN_CHUNK = 10000;
export const FIRST_CHUNK = 100000;
const CONTINUOUS_MS = 500;  // frames further apart are not a run: no adaptation
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
    this.marker.visible = false;
    this.overlay = new Scene();
    this.overlayGroup = new Group();
    this.overlay.add(this.overlayGroup);
    this.overlayGroup.add(this.marker);
    this.order = null;  // drawn slot -> point index
    this.drawn = 0;  // slots drawn in the current picture
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
    this.chunk = FIRST_CHUNK;
    this.restart = true;
    this.lastTick = null;  // time of the previous frame of an uninterrupted run of frames
    this.frameRequested = false;
    this.frames = 0;
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
      view.overlayGroup.quaternion.copy(this.quaternion);
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
    for (const view of this.views) {
      view.group.quaternion.copy(this.quaternion);
      view.overlayGroup.quaternion.copy(this.quaternion);
    }
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
    this.requestRender();
  }

  /** Draw again from the first chunk at the next animation frame. */
  requestRender() {
    this.restart = true;
    this._schedule();
  }

  _schedule() {
    if (this.frameRequested) return;
    this.frameRequested = true;
    requestAnimationFrame((now) => {
      this.frameRequested = false;
      // Back-to-back frames: the interval is the cost of the previous frame's points.
      if (this.lastTick !== null && now - this.lastTick < CONTINUOUS_MS) {
        this._adapt(now - this.lastTick);
      }
      const more = this.render();
      this.lastTick = now;
      if (more) this._schedule();
    });
  }

  /** The chunk that makes a frame take FRAME_MS at the cost per point just seen. */
  _adapt(interval) {
    if (!(interval > 0) || !this.lastChunk) return;
    const total = this.views.reduce((sum, v) => sum + v.n, 0);
    const wanted = (FRAME_MS / interval) * this.lastChunk;
    const bounded = Math.min(2 * this.chunk, Math.max(0.25 * this.chunk, wanted));
    this.chunk = Math.round(Math.max(MIN_CHUNK, Math.min(Math.max(total, MIN_CHUNK), bounded)));
  }

  /**
   * Draw the next chunk of every view (from the first after a change, clearing the picture).
   * @param {number} [chunk] points to draw in all views together (default: the adapted chunk)
   * @returns {boolean} whether points are left to draw
   */
  render(chunk = this.chunk) {
    const width = this.canvas.clientWidth / this.views.length;  // CSS pixels, as three.js
    const height = this.canvas.clientHeight;
    const restart = this.restart;
    this.restart = false;
    this.renderer.autoClear = false;
    if (restart) {
      this.renderer.setScissor(0, 0, this.canvas.clientWidth, height);
      this.renderer.clear();
      for (const view of this.views) view.drawn = 0;
    }
    const share = Math.max(1, Math.floor(chunk / this.views.length));
    let drawn = 0;
    let left = false;
    this.views.forEach((view, k) => {
      const count = Math.max(0, Math.min(share, view.n - view.drawn));
      view.material.uniforms.pointSize.value = this.pointSize * this.renderer.getPixelRatio();
      this.renderer.setViewport(k * width, 0, width, height);
      this.renderer.setScissor(k * width, 0, width, height);
      if (count > 0) {
        view.geometry.setDrawRange(view.drawn, count);
        this.renderer.render(view.scene, this.camera);
        view.drawn += count;
        drawn += count;
        // The marker goes over the finished picture (later chunks would cover it).
        if (view.drawn >= view.n && view.marker.visible) {
          this.renderer.render(view.overlay, this.camera);
        }
      }
      if (view.drawn < view.n) left = true;
    });
    this.lastChunk = drawn;
    this.frames++;
    if (this.onrender) {
      this.onrender({ drawn: this.views.reduce((sum, v) => sum + v.drawn, 0), chunk: drawn });
    }
    return left;
  }

  /** Milliseconds of `frames` frames while the camera turns around the cloud, each waited
   * for (a pixel read back): each frame starts a new picture with `chunk` points. */
  measure(frames, chunk) {
    const gl = this.renderer.getContext();
    const pixel = new Uint8Array(4);
    const times = [];
    for (let i = 0; i < frames; i++) {
      const start = performance.now();
      this.rotate(360 / frames, 0);
      this.restart = true;
      this.render(chunk);
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);
      times.push(performance.now() - start);
    }
    this.requestRender();
    return times;
  }

  /** Turn the camera continuously for `seconds` as a user would (each animation frame a
   * step), then stop; resolves to the frames per second while turning, the chunk it settled
   * on and the seconds until the still picture held every point. */
  spin(seconds, degreesPerFrame = 2) {
    return new Promise((resolve) => {
      const start = performance.now();
      const first = this.frames;
      const step = () => {
        if (performance.now() - start < seconds * 1000) {
          this.rotate(degreesPerFrame, 0);
          this.requestRender();
          requestAnimationFrame(step);
          return;
        }
        const turning = (this.frames - first) / ((performance.now() - start) / 1000);
        const chunk = this.chunk;
        const stopped = performance.now();
        const wait = () => {
          if (this.frameRequested || this.views.some((v) => v.drawn < v.n)) {
            requestAnimationFrame(wait);
            return;
          }
          resolve({ fps: turning, chunk, complete_s: (performance.now() - stopped) / 1000 });
        };
        requestAnimationFrame(wait);
      };
      requestAnimationFrame(step);
    });
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
