// The viewer panel of the jobs page: loads a finished job's positions and one field at a time
// (float32 from /v1/jobs/{id}/result/fields/{name}), colors the cloud, shows the histogram
// with draggable limits and the color bar, picks points (every field of the point from
// /v1/jobs/{id}/result/points/{index}), and compares two jobs side by side or as a difference.
import { DIVERGING, SEQUENTIAL, categorical, cssColor } from "./colormaps.js";
import { Histogram } from "./histogram.js";
import { PointScene } from "./scene.js";
import { defaultLimits, finiteSorted, histogramDomain } from "./stats.js";

const AXES = { x: [1, 0, 0], "-x": [-1, 0, 0], y: [0, 1, 0], "-y": [0, -1, 0],
  z: [0, 0, 1], "-z": [0, 0, -1] };
const DEFAULT_FIELD = "mean";
const CACHED_FIELDS = 4;  // per job: switching back is instant, memory stays bounded
const CLICK_PIXELS = 4;
const STATUS_MS = 500;  // a press and release closer than this is a pick, not a turn
const $ = (id) => document.getElementById(id);

function element(tag, attrs = {}, text) {
  const node = document.createElement(tag);
  for (const [name, value] of Object.entries(attrs)) node.setAttribute(name, value);
  if (text !== undefined) node.textContent = text;
  return node;
}

function formatNumber(value) {
  if (value === null || value === undefined) return "—";
  if (Array.isArray(value)) return value.map(formatNumber).join(", ");
  if (typeof value !== "number") return String(value);
  if (Number.isInteger(value)) return value.toLocaleString("en-US");
  const magnitude = Math.abs(value);
  return magnitude !== 0 && (magnitude < 1e-3 || magnitude >= 1e5)
    ? value.toExponential(4) : Number(value.toPrecision(5)).toString();
}

/** Name an up vector: an axis ("-y") or its rounded components. */
function upName(up) {
  for (const [name, axis] of Object.entries(AXES)) {
    if (axis.every((c, i) => Math.abs(c - up[i]) < 1e-6)) return name;
  }
  return "(" + up.map((c) => c.toFixed(2)).join(", ") + ")";
}

/** One job's result as the viewer needs it: listing, positions and a few fields. */
class JobData {
  constructor(api, job) {
    this.api = api;
    this.job = job;
    this.listing = null;
    this.positions = null;
    this.fields = new Map();
  }

  url(path) {
    return `/v1/jobs/${encodeURIComponent(this.job.id)}/result/${path}`;
  }

  async floats(path) {
    const response = await this.api(this.url(path));
    return new Float32Array(await response.arrayBuffer());
  }

  async load() {
    this.listing = await (await this.api(this.url("fields"))).json();
    this.positions = await this.floats("fields/points");
    return this;
  }

  entry(name) {
    return this.listing.fields.find((f) => f.name === name) || null;
  }

  async field(name) {
    if (!this.fields.has(name)) {
      if (this.fields.size >= CACHED_FIELDS) this.fields.delete(this.fields.keys().next().value);
      this.fields.set(name, this.floats(`fields/${encodeURIComponent(name)}`));
    }
    try {
      return await this.fields.get(name);
    } catch (err) {
      this.fields.delete(name);
      throw err;
    }
  }

  async point(index) {
    return (await this.api(this.url(`points/${index}`))).json();
  }
}

function sameCloud(a, b) {
  if (a.positions.length !== b.positions.length) return false;
  for (let i = 0; i < a.positions.length; i++) {
    if (a.positions[i] !== b.positions[i]) return false;
  }
  return true;
}

export class ViewerPanel {
  /**
   * @param {{api: Function, explain: Function, message: Function}} page the page's fetch
   *   with the API key, its error wording and its status line
   */
  constructor(page) {
    this.page = page;
    this.scene = null;
    this.a = null;
    this.b = null;
    this.mode = "side";
    this.fieldName = DEFAULT_FIELD;
    this.limits = null;
    this.defaults = null;
    this.jobs = [];
    this.busy = false;
    this.lastPick = null;
    this.histogram = new Histogram($("viewer-histogram"),
      (vmin, vmax) => this.setLimits(vmin, vmax), () => this.resetLimits());
    $("viewer-field").addEventListener("change", () => this.selectField($("viewer-field").value));
    $("viewer-up").addEventListener("change", () => this.applyUp());
    $("viewer-size").addEventListener("input", () => {
      if (this.scene) this.scene.setPointSize(Number($("viewer-size").value));
    });
    $("viewer-compare").addEventListener("change", () => this.compare());
    $("viewer-compare-mode").addEventListener("change", () => this.compare());
    $("viewer-close").addEventListener("click", () => this.close());
    $("viewer-reset-limits").addEventListener("click", () => this.resetLimits());
    for (const id of ["viewer-vmin", "viewer-vmax"]) {
      $(id).addEventListener("change", () => this.setLimits(Number($("viewer-vmin").value),
        Number($("viewer-vmax").value)));
    }
    this.bindPicking($("viewer-canvas"));
  }

  bindPicking(canvas) {
    let press = null;
    canvas.addEventListener("pointerdown", (e) => { press = { x: e.clientX, y: e.clientY }; });
    canvas.addEventListener("pointerup", (e) => {
      if (!press || e.button !== 0) return;
      const moved = Math.hypot(e.clientX - press.x, e.clientY - press.y);
      press = null;
      if (moved > CLICK_PIXELS) return;
      const rect = canvas.getBoundingClientRect();
      this.pickAt(e.clientX - rect.left, e.clientY - rect.top);
    });
  }

  ensureScene() {
    if (!this.scene) {
      this.scene = new PointScene($("viewer-canvas"));
      this.scene.onrender = (frame) => this.describeFrame(frame);
    }
    return this.scene;
  }

  /** Open a succeeded job (a job document of GET /v1/jobs). */
  async open(job) {
    $("viewer-section").hidden = false;
    $("viewer-title").textContent = `Job ${job.id}` +
      (job.input && job.input.filename ? ` · ${job.input.filename}` : "") + ` · ${job.method}`;
    await this.run(async () => {
      const scene = this.ensureScene();
      this.a = await new JobData(this.page.api, job).load();
      this.b = null;
      $("viewer-compare").value = "";
      this.fillFields();
      this.fillCompare();
      $("viewer-up").options[0].textContent = `auto (${upName(this.a.listing.up)})`;
      $("viewer-up").value = "auto";
      scene.setViewCount(1);
      scene.setUp(this.a.listing.up);
      scene.setCloud(0, this.a.positions);
      this.clearPick();
      await this.show();
    });
    $("viewer-section").scrollIntoView({ block: "nearest" });
  }

  close() {
    $("viewer-section").hidden = true;
    this.a = null;
    this.b = null;
  }

  /** Run a loading step with the panel marked busy; errors go to the page's message line. */
  async run(step) {
    this.busy = true;
    $("viewer-loading").hidden = false;
    try {
      await step();
    } catch (err) {
      this.page.message("Viewer: " + this.page.explain(err), "error");
    } finally {
      this.busy = false;
      $("viewer-loading").hidden = true;
    }
  }

  fillFields() {
    const select = $("viewer-field");
    select.replaceChildren();
    const scalars = this.a.listing.fields.filter((f) => f.components === 1);
    for (const f of scalars) {
      select.append(element("option", { value: f.name }, `${f.label} (${f.name})`));
    }
    if (!scalars.some((f) => f.name === this.fieldName)) {
      this.fieldName = scalars.some((f) => f.name === DEFAULT_FIELD) ? DEFAULT_FIELD
        : scalars[0].name;
    }
    select.value = this.fieldName;
  }

  /** Jobs offered for comparison: the page's succeeded jobs of the same size as A. */
  setJobs(jobs) {
    this.jobs = jobs.filter((j) => j.status === "succeeded");
    if (this.a) this.fillCompare();
  }

  fillCompare() {
    const select = $("viewer-compare");
    const chosen = select.value;
    select.replaceChildren(element("option", { value: "" }, "nothing"));
    for (const job of this.jobs) {
      if (job.id === this.a.job.id || job.n_points !== this.a.job.n_points) continue;
      const name = (job.input && job.input.filename) || "arrays";
      select.append(element("option", { value: job.id },
        `${name} · ${job.method} · ${job.id.slice(0, 8)}`));
    }
    select.value = [...select.options].some((o) => o.value === chosen) ? chosen : "";
  }

  async compare() {
    const id = $("viewer-compare").value;
    this.mode = $("viewer-compare-mode").value;
    await this.run(async () => {
      const scene = this.ensureScene();
      if (!id) {
        this.b = null;
      } else if (!this.b || this.b.job.id !== id) {
        const job = this.jobs.find((j) => j.id === id);
        this.b = await new JobData(this.page.api, job).load();
        this.b.same = sameCloud(this.a, this.b);
      }
      if (this.b && this.mode === "difference" && !this.b.same) {
        this.mode = "side";
        $("viewer-compare-mode").value = "side";
        this.page.message("The difference needs two jobs of the same cloud (the same points "
          + "in the same order); showing them side by side instead.", "error");
      }
      const split = this.b && this.mode === "side";
      scene.setViewCount(split ? 2 : 1);
      scene.setCloud(0, this.a.positions);
      if (split) scene.setCloud(1, this.b.positions, this.b.same ? scene.views[0] : null);
      scene.frame();
      this.clearPick();
      await this.show();
    });
  }

  applyUp() {
    if (!this.scene || !this.a) return;
    const choice = $("viewer-up").value;
    this.scene.setUp(choice === "auto" ? this.a.listing.up : AXES[choice]);
  }

  async selectField(name) {
    this.fieldName = name;
    await this.run(() => this.show());
  }

  /** The arrays to draw for the current field: one per view. */
  async displayed() {
    const a = await this.a.field(this.fieldName);
    if (!this.b) return [a];
    if (!this.b.entry(this.fieldName)) {
      throw new Error(`the compared job has no field ${this.fieldName}`);
    }
    const b = await this.b.field(this.fieldName);
    if (this.mode !== "difference") return [a, b];
    const diff = new Float32Array(a.length);
    for (let i = 0; i < a.length; i++) diff[i] = a[i] - b[i];
    return [diff];
  }

  entry() {
    const base = this.a.entry(this.fieldName);
    if (this.b && this.mode === "difference") {
      return { ...base, label: `${base.label}, A − B`, scale: "diverging", limits: null,
        categories: null };
    }
    return base;
  }

  async show() {
    const arrays = await this.displayed();
    arrays.forEach((values, k) => this.scene.setValues(k, values));
    let all = arrays[0];
    if (arrays.length > 1) {
      all = new Float32Array(arrays[0].length + arrays[1].length);
      all.set(arrays[0]);
      all.set(arrays[1], arrays[0].length);
    }
    this.sorted = finiteSorted(all);
    this.defaults = defaultLimits(this.sorted, this.entry());
    this.limits = { ...this.defaults };
    this.domain = histogramDomain(this.sorted, this.limits);
    this.applyLimits(true);
  }

  lut() {
    if (this.limits.mode === "categorical") return categorical(Math.round(this.limits.vmax + 0.5));
    return this.limits.mode === "diverging" ? DIVERGING : SEQUENTIAL;
  }

  setLimits(vmin, vmax) {
    if (!this.limits || !Number.isFinite(vmin) || !Number.isFinite(vmax) || !(vmax > vmin)) {
      return;
    }
    this.limits = { ...this.limits, vmin, vmax };
    this.applyLimits(false);
  }

  resetLimits() {
    if (!this.defaults) return;
    this.limits = { ...this.defaults };
    this.applyLimits(true);
  }

  applyLimits(redrawHistogram) {
    const lut = this.lut();
    const { vmin, vmax, mode } = this.limits;
    this.scene.setColoring(vmin, vmax, mode, lut);
    if (redrawHistogram) this.histogram.set(this.sorted, this.domain, this.limits, lut);
    else this.histogram.setLimits(this.limits);
    $("viewer-vmin").value = Number(vmin.toPrecision(6));
    $("viewer-vmax").value = Number(vmax.toPrecision(6));
    const categoricalField = mode === "categorical";
    $("viewer-limits").hidden = categoricalField;
    this.drawLegend(lut);
  }

  drawLegend(lut) {
    const entry = this.entry();
    const legend = $("viewer-legend");
    legend.replaceChildren();
    const title = element("div", { class: "legend-title" },
      entry.unit ? `${entry.label} [${entry.unit}]` : entry.label);
    legend.append(title);
    if (this.limits.mode === "categorical") {
      const list = element("ul", { class: "legend-categories" });
      const names = entry.categories || {};
      const count = lut.length / 4;
      for (let code = 0; code < count; code++) {
        const item = element("li");
        const swatch = element("span", { class: "swatch" });
        swatch.style.background = cssColor(lut, (code + 0.5) / count);
        item.append(swatch, ` ${code} ${names[code] || ""}`);
        list.append(item);
      }
      legend.append(list);
      return;
    }
    const bar = element("canvas", { width: "256", height: "14", class: "legend-bar" });
    const ctx = bar.getContext("2d");
    for (let x = 0; x < 256; x++) {
      ctx.fillStyle = cssColor(lut, x / 255);
      ctx.fillRect(x, 0, 1, 14);
    }
    const ticks = element("div", { class: "legend-ticks" });
    const { vmin, vmax, mode } = this.limits;
    ticks.append(element("span", {}, formatNumber(vmin)));
    if (mode === "diverging" && vmin < 0 && vmax > 0) ticks.append(element("span", {}, "0"));
    ticks.append(element("span", {}, formatNumber(vmax)));
    legend.append(bar, ticks);
  }

  describeFrame({ drawn }) {
    const total = this.scene.views.reduce((sum, v) => sum + v.n, 0);
    // At most a few times a second: a text change costs the page a layout and a repaint,
    // which would slow every frame while the camera turns.
    const now = performance.now();
    if (drawn < total && now - (this.described || 0) < STATUS_MS) return;
    this.described = now;
    const status = $("viewer-status");
    status.dataset.drawn = String(drawn);
    status.textContent = `${total.toLocaleString("en-US")} points` + (drawn < total
      ? `, ${drawn.toLocaleString("en-US")} drawn so far (a uniform sample; the rest fill in `
        + "when the camera stops)." : ", all drawn.");
  }

  clearPick() {
    this.lastPick = null;
    $("viewer-pick").replaceChildren();
    if (this.scene) this.scene.mark(null);
  }

  /** Pick the point at canvas position (x, y) in CSS pixels and show its fields. */
  async pickAt(x, y) {
    if (!this.scene || !this.a || this.busy) return null;
    const hit = this.scene.pick(x, y);
    if (!hit) return null;
    await this.run(async () => {
      const jobs = this.b ? [this.a, this.b] : [this.a];
      const values = await Promise.all(jobs.map((job) => job.point(hit.index)));
      this.scene.mark(hit.index);
      this.showPick(hit.index, jobs, values);
      this.lastPick = { index: hit.index, view: hit.view, values: values.map((v) => v.fields) };
    });
    return this.lastPick;
  }

  showPick(index, jobs, values) {
    const table = $("viewer-pick");
    const head = element("tr");
    head.append(element("th", {}, `point ${index.toLocaleString("en-US")}`));
    jobs.forEach((job, k) => head.append(element("th", {}, jobs.length > 1
      ? `${k ? "B" : "A"} · ${job.job.method}` : job.job.method)));
    const body = [head];
    for (const name of Object.keys(values[0].fields)) {
      const row = element("tr", { "data-field": name });
      const entry = this.a.entry(name);
      row.append(element("th", {}, entry && entry.unit ? `${name} [${entry.unit}]` : name));
      for (const doc of values) {
        const value = doc.fields[name];
        row.append(element("td", { "data-value": JSON.stringify(value === undefined ? null
          : value) }, formatNumber(value)));
      }
      body.push(row);
    }
    table.replaceChildren(...body);
  }
}
