// Entry of the viewer bundle: the page's script (service/static/app.js) creates the panel.
import { ViewerPanel } from "./panel.js";
import { FRAME_MS, MIN_CHUNK } from "./scene.js";
import { median } from "./stats.js";

window.CurvatureViewer = { ViewerPanel, FRAME_MS, MIN_CHUNK, median };
