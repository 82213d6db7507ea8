// The jobs page: lists the caller's jobs (GET /v1/jobs) with status, progress and preview
// thumbnails, submits files (POST /v1/jobs) and follows the submitted job until the viewer
// (viewer.js, the bundle built from web/) opens it. Every request carries the API key from
// localStorage as a Bearer token, so previews and downloads are fetched as blobs (an <img src>
// or <a href> could not send the header).
"use strict";

const KEY_STORAGE = "curvature.apiKey";
const REFRESH_BUSY_MS = 2000;   // while a job is queued or running
const REFRESH_IDLE_MS = 10000;
const PAGE_SIZE = 50;
const FOLLOW_MS = 1000;         // polling of the job submitted from this page

const $ = (id) => document.getElementById(id);
const thumbnails = new Map();   // "id|field|view" -> Promise of an object URL (or null)
let refreshTimer = null;
let followTimer = null;
let viewer = null;              // the ViewerPanel, when the bundle loaded

class ApiError extends Error {
  constructor(status, problem) {
    const text = problem && (problem.title || problem.detail)
      ? `${problem.title || "Error"}${problem.detail ? ": " + problem.detail : ""}`
      : `HTTP ${status}`;
    super(text);
    this.status = status;
    this.problem = problem;
  }
}

function apiKey() {
  return localStorage.getItem(KEY_STORAGE) || "";
}

async function api(path, options = {}) {
  const headers = Object.assign({}, options.headers || {});
  const key = apiKey();
  if (key) headers["Authorization"] = "Bearer " + key;
  const response = await fetch(path, Object.assign({}, options, { headers }));
  if (!response.ok) {
    let problem = null;
    try { problem = await response.json(); } catch (err) { /* not a problem document */ }
    throw new ApiError(response.status, problem);
  }
  return response;
}

function showMessage(text, kind) {
  const box = $("message");
  box.textContent = text;
  box.className = kind || "";
}

function explain(err) {
  if (err instanceof ApiError && err.status === 401) {
    return "This service needs an API key: enter yours above. (" + err.message + ")";
  }
  return err.message || String(err);
}

function element(tag, attrs = {}, text) {
  const node = document.createElement(tag);
  for (const [name, value] of Object.entries(attrs)) node.setAttribute(name, value);
  if (text !== undefined) node.textContent = text;
  return node;
}

// -- methods and the submit form -----------------------------------------------------------

let methodInfo = {};

async function loadMethods() {
  const doc = await (await api("/v1/methods")).json();
  const methodSelect = $("method");
  methodSelect.replaceChildren();
  for (const method of doc.methods) {
    methodInfo[method.name] = method;
    const option = element("option", { value: method.name }, method.name);
    if (method.name === doc.default_method) option.selected = true;
    methodSelect.append(option);
  }
  const fitSelect = $("fit");
  fitSelect.replaceChildren(element("option", { value: "" }, "method's default"));
  for (const fit of doc.fits) fitSelect.append(element("option", { value: fit.name }, fit.name));
  describeMethod();
}

function describeMethod() {
  const method = methodInfo[$("method").value];
  if (!method) return;
  const params = method.parameters.map((p) => `${p.name}=${p.default}`).join(", ");
  $("method-help").textContent = `${method.name}: ${method.description}` +
    (params ? ` Parameters: ${params}.` : "");
}

async function submitJob(event) {
  event.preventDefault();
  const file = $("file").files[0];
  if (!file) { showMessage("Choose a file first.", "error"); return; }
  const params = { method: $("method").value };
  if ($("fit").value) params.fit = $("fit").value;
  const extra = $("extra-params").value.trim();
  if (extra) {
    let parsed;
    try { parsed = JSON.parse(extra); } catch (err) {
      showMessage("More parameters must be a JSON object, e.g. {\"k\": 24}.", "error");
      return;
    }
    if (parsed === null || typeof parsed !== "object" || Array.isArray(parsed)) {
      showMessage("More parameters must be a JSON object, e.g. {\"k\": 24}.", "error");
      return;
    }
    Object.assign(params, parsed);
  }
  const body = new FormData();
  body.append("file", file, file.name);
  body.append("params", JSON.stringify(params));
  $("submit-button").disabled = true;
  try {
    const job = await (await api("/v1/jobs", { method: "POST", body })).json();
    showMessage(`Job ${job.id} submitted (${file.name}, ${params.method}).`, "ok");
    $("submit-form").reset();
    describeMethod();
    follow(job);
    await refresh();
  } catch (err) {
    showMessage("Not submitted: " + explain(err), "error");
  } finally {
    $("submit-button").disabled = false;
  }
}

// -- the job submitted from this page: progress, then the viewer -----------------------------

function showProgress(job) {
  $("job-progress").hidden = false;
  $("job-progress").dataset.status = job.status;
  $("job-progress-bar").value = job.progress;
  const percent = Math.round(job.progress * 100);
  const detail = job.error ? `: ${job.error.detail || job.error.title}` : "";
  $("job-progress-text").textContent = `Job ${job.id}: ${job.status}, ${percent} %${detail}`;
}

function follow(job) {
  clearTimeout(followTimer);
  showProgress(job);
  if (job.status === "succeeded") {
    if (viewer) viewer.open(job);
    return;
  }
  if (["failed", "cancelled"].includes(job.status)) return;
  followTimer = setTimeout(async () => {
    try {
      follow(await (await api(`/v1/jobs/${encodeURIComponent(job.id)}`)).json());
    } catch (err) {
      showMessage("Lost track of the job: " + explain(err), "error");
    }
  }, FOLLOW_MS);
}

// -- the jobs table ------------------------------------------------------------------------

function previewChoice() {
  return { field: $("preview-field").value, view: $("preview-view").value };
}

function thumbnailUrl(jobId) {
  const { field, view } = previewChoice();
  const key = `${jobId}|${field}|${view}`;
  if (!thumbnails.has(key)) {
    const query = new URLSearchParams({ field, view });
    const promise = api(`/v1/jobs/${encodeURIComponent(jobId)}/preview.png?${query}`)
      .then((response) => response.blob())
      .then((blob) => URL.createObjectURL(blob))
      .catch(() => { thumbnails.delete(key); return null; });  // retried at next refresh
    thumbnails.set(key, promise);
  }
  return thumbnails.get(key);
}

function previewCell(job) {
  const cell = element("td", { class: "preview" });
  if (job.status !== "succeeded") return cell;
  const { field } = previewChoice();
  const img = element("img", { class: "thumb", alt: `${field} curvature of job ${job.id}` });
  thumbnailUrl(job.id).then((url) => {
    if (url) img.src = url;
    else img.replaceWith(element("span", { class: "hint" }, "no preview"));
  });
  img.addEventListener("click", () => {
    $("large-image").src = img.src;
    $("large-preview").showModal();
  });
  cell.append(img);
  return cell;
}

async function download(job, format) {
  try {
    const response = await api(`/v1/jobs/${encodeURIComponent(job.id)}/result?format=${format}`);
    const url = URL.createObjectURL(await response.blob());
    const link = element("a", { href: url, download: `${job.id}.${format}` });
    document.body.append(link);
    link.click();
    link.remove();
    setTimeout(() => URL.revokeObjectURL(url), 10000);
  } catch (err) {
    showMessage("Download failed: " + explain(err), "error");
  }
}

async function removeJob(job) {
  const final = ["succeeded", "failed", "cancelled"].includes(job.status);
  try {
    await api(`/v1/jobs/${encodeURIComponent(job.id)}`, { method: "DELETE" });
    showMessage(`Job ${job.id} ${final ? "deleted" : "cancelled"}.`, "ok");
  } catch (err) {
    showMessage(explain(err), "error");
  }
  await refresh();
}

function actionsCell(job) {
  const cell = element("td", { class: "actions" });
  if (job.status === "succeeded") {
    const select = element("select", { "aria-label": "result format" });
    for (const format of (job.result && job.result.formats) || ["ply"]) {
      select.append(element("option", { value: format }, format));
    }
    select.value = "ply";
    const button = element("button", { type: "button" }, "Download");
    button.addEventListener("click", () => download(job, select.value));
    cell.append(select, " ", button, " ");
    if (viewer) {
      const view = element("button", { type: "button", class: "view" }, "View");
      view.addEventListener("click", () => viewer.open(job));
      cell.append(view, " ");
    }
  }
  const final = ["succeeded", "failed", "cancelled"].includes(job.status);
  const remove = element("button", { type: "button" }, final ? "Delete" : "Cancel");
  remove.addEventListener("click", () => removeJob(job));
  cell.append(remove);
  return cell;
}

function jobRow(job) {
  const row = element("tr", { "data-job-id": job.id, "data-status": job.status });
  const created = new Date(job.created_at);
  row.append(element("td", {}, created.toLocaleString()));
  row.append(element("td", { class: "id" }, job.id));
  const input = job.input || {};
  row.append(element("td", {}, input.filename || (input.kind === "arrays" ? "arrays" : "")));
  row.append(element("td", {}, job.method));
  row.append(element("td", {}, job.n_points == null ? "" : job.n_points.toLocaleString()));
  const status = element("td", { class: `status status-${job.status}` }, job.status);
  if (job.error) status.append(element("div", { class: "error-detail" }, job.error.detail || ""));
  row.append(status);
  const progressCell = element("td", { class: "progress" });
  const bar = element("progress", { max: "1", value: String(job.progress) });
  progressCell.append(bar, " " + Math.round(job.progress * 100) + " %");
  row.append(progressCell);
  row.append(previewCell(job));
  row.append(actionsCell(job));
  return row;
}

function renderJobs(items) {
  const body = $("jobs-body");
  if (!items.length) {
    const row = element("tr", { class: "empty" });
    row.append(element("td", { colspan: "9" }, "No jobs yet: submit a file above."));
    body.replaceChildren(row);
    return;
  }
  body.replaceChildren(...items.map(jobRow));
}

async function refresh() {
  clearTimeout(refreshTimer);
  let busy = false;
  try {
    const page = await (await api(`/v1/jobs?limit=${PAGE_SIZE}`)).json();
    renderJobs(page.items);
    if (viewer) viewer.setJobs(page.items);
    busy = page.items.some((job) => job.status === "queued" || job.status === "running");
    $("updated").textContent = "updated " + new Date().toLocaleTimeString();
  } catch (err) {
    showMessage(explain(err), "error");
    $("jobs-body").replaceChildren();
  }
  refreshTimer = setTimeout(refresh, busy ? REFRESH_BUSY_MS : REFRESH_IDLE_MS);
}

// -- start ---------------------------------------------------------------------------------

function saveKey(event) {
  event.preventDefault();
  localStorage.setItem(KEY_STORAGE, $("api-key").value.trim());
  thumbnails.clear();  // another key sees other jobs
  showMessage("API key saved in this browser.", "ok");
  start();
}

function forgetKey() {
  localStorage.removeItem(KEY_STORAGE);
  $("api-key").value = "";
  thumbnails.clear();
  showMessage("API key forgotten.", "ok");
  start();
}

async function start() {
  try {
    await loadMethods();
  } catch (err) {
    showMessage(explain(err), "error");
  }
  await refresh();
}

document.addEventListener("DOMContentLoaded", () => {
  if (window.CurvatureViewer) {
    viewer = new window.CurvatureViewer.ViewerPanel({ api, explain, message: showMessage });
    window.curvatureViewer = viewer;  // for the browser tests and benchmarks/viewer_fps.py
  }
  $("api-key").value = apiKey();
  $("key-form").addEventListener("submit", saveKey);
  $("forget-key").addEventListener("click", forgetKey);
  $("submit-form").addEventListener("submit", submitJob);
  $("method").addEventListener("change", describeMethod);
  $("refresh").addEventListener("click", refresh);
  for (const id of ["preview-field", "preview-view"]) $(id).addEventListener("change", refresh);
  start();
});
