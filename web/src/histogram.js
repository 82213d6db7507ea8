// The histogram of the colored field, drawn with each bar in its color, with the two color
// limits as handles: drag a handle to move one limit, drag across the histogram to set both,
// double-click to return to the percentile limits.
import { cssColor } from "./colormaps.js";
import { histogram } from "./stats.js";

const PAD = 8;  // px left and right of the bars
const GRAB = 7;  // px within which a press takes a handle

export class Histogram {
  /**
   * @param {HTMLCanvasElement} canvas
   * @param {(vmin: number, vmax: number) => void} onchange the user moved the limits
   * @param {() => void} onreset the user asked for the default limits
   */
  constructor(canvas, onchange, onreset) {
    this.canvas = canvas;
    this.onchange = onchange;
    this.onreset = onreset;
    this.state = null;
    this.drag = null;
    canvas.addEventListener("pointerdown", (e) => this.press(e));
    canvas.addEventListener("pointermove", (e) => this.move(e));
    canvas.addEventListener("pointerup", (e) => this.release(e));
    canvas.addEventListener("dblclick", () => this.onreset());
  }

  /** Show `sorted` (finite values, ascending) over `domain` [lo, hi] with `limits`. */
  set(sorted, domain, limits, lut) {
    this.state = { counts: histogram(sorted, domain[0], domain[1]), domain, limits, lut };
    this.draw();
  }

  setLimits(limits) {
    if (!this.state) return;
    this.state.limits = limits;
    this.draw();
  }

  xOf(value) {
    const [lo, hi] = this.state.domain;
    return PAD + ((value - lo) / (hi - lo)) * (this.canvas.width - 2 * PAD);
  }

  valueOf(x) {
    const [lo, hi] = this.state.domain;
    const t = Math.min(1, Math.max(0, (x - PAD) / (this.canvas.width - 2 * PAD)));
    return lo + t * (hi - lo);
  }

  _x(event) {
    const rect = this.canvas.getBoundingClientRect();
    return ((event.clientX - rect.left) * this.canvas.width) / rect.width;
  }

  press(event) {
    if (!this.state || event.button !== 0) return;
    const x = this._x(event);
    const { vmin, vmax } = this.state.limits;
    const dMin = Math.abs(x - this.xOf(vmin));
    const dMax = Math.abs(x - this.xOf(vmax));
    if (Math.min(dMin, dMax) <= GRAB) {
      this.drag = { handle: dMin <= dMax ? "vmin" : "vmax" };
    } else {
      this.drag = { handle: "range", from: this.valueOf(x) };
    }
    this.canvas.setPointerCapture(event.pointerId);
    event.preventDefault();
  }

  move(event) {
    if (!this.drag) return;
    const value = this.valueOf(this._x(event));
    let { vmin, vmax, mode } = this.state.limits;
    if (this.drag.handle === "vmin") vmin = value;
    else if (this.drag.handle === "vmax") vmax = value;
    else { vmin = Math.min(this.drag.from, value); vmax = Math.max(this.drag.from, value); }
    const [lo, hi] = this.state.domain;
    const eps = 1e-6 * (hi - lo);
    if (mode === "diverging") {  // the map stays centred on 0: one limit on each side
      vmin = Math.min(vmin, -eps);
      vmax = Math.max(vmax, eps);
    }
    if (vmax - vmin < eps) {
      if (this.drag.handle === "vmin") vmin = vmax - eps; else vmax = vmin + eps;
    }
    this.onchange(vmin, vmax);
  }

  release(event) {
    if (!this.drag) return;
    this.move(event);
    this.drag = null;
  }

  draw() {
    const ctx = this.canvas.getContext("2d");
    const { width, height } = this.canvas;
    ctx.clearRect(0, 0, width, height);
    if (!this.state) return;
    const { counts, domain, limits, lut } = this.state;
    const top = 4;
    const bottom = height - 4;
    const peak = Math.max(1, ...counts);
    const barWidth = (width - 2 * PAD) / counts.length;
    const [lo, hi] = domain;
    for (let i = 0; i < counts.length; i++) {
      const value = lo + ((i + 0.5) / counts.length) * (hi - lo);
      ctx.fillStyle = cssColor(lut, this.position(value, limits));
      const h = (counts[i] / peak) * (bottom - top);
      ctx.fillRect(PAD + i * barWidth, bottom - h, Math.max(barWidth - 0.5, 0.5), h);
    }
    ctx.strokeStyle = "#8d99ae";
    ctx.beginPath();
    ctx.moveTo(PAD, bottom + 0.5);
    ctx.lineTo(width - PAD, bottom + 0.5);
    ctx.stroke();
    if (limits.mode === "diverging" && lo < 0 && hi > 0) {
      ctx.setLineDash([3, 3]);
      ctx.beginPath();
      ctx.moveTo(this.xOf(0) + 0.5, top);
      ctx.lineTo(this.xOf(0) + 0.5, bottom);
      ctx.stroke();
      ctx.setLineDash([]);
    }
    ctx.fillStyle = "#1d2330";
    for (const value of [limits.vmin, limits.vmax]) {
      const x = Math.round(this.xOf(value)) + 0.5;
      ctx.fillRect(x - 1, top, 2, bottom - top);
      ctx.fillRect(x - 4, top, 8, 6);
    }
  }

  /** Position in the color map (0..1) of a value under the current limits. */
  position(value, limits) {
    const { vmin, vmax, mode } = limits;
    let t;
    if (mode === "diverging" && vmin < 0 && vmax > 0) {
      t = value < 0 ? 0.5 - (0.5 * value) / vmin : 0.5 + (0.5 * value) / vmax;
    } else {
      t = (value - vmin) / (vmax - vmin);
    }
    return Math.min(1, Math.max(0, t));
  }
}
