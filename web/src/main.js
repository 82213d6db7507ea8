// Entry of the viewer bundle: the page's script (service/static/app.js) creates the panel.
import { ViewerPanel } from "./panel.js";
import { MOVING_BUDGET } from "./scene.js";
import { median } from "./stats.js";

window.CurvatureViewer = { ViewerPanel, MOVING_BUDGET, median };
