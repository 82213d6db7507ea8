// Color maps as 256-entry RGBA lookup tables, built by linear interpolation between anchor
// colors (sRGB, 0-255), and the categorical palette of status codes.

// Diverging: ColorBrewer RdBu, 11 classes (Cynthia A. Brewer, colorbrewer2.org), reversed so
// that negative values are blue and positive red, like the PNG previews (matplotlib RdBu_r).
const RDBU_R = [
  [5, 48, 97], [33, 102, 172], [67, 147, 195], [146, 197, 222], [209, 229, 240],
  [247, 247, 247], [253, 219, 199], [244, 165, 130], [214, 96, 77], [178, 24, 43],
  [103, 0, 31],
];
// Sequential: viridis (S. van der Walt and N. Smith, matplotlib; CC0) at 9 even stops.
const VIRIDIS = [
  [68, 1, 84], [71, 45, 123], [59, 82, 139], [44, 114, 142], [33, 145, 140],
  [40, 174, 128], [94, 201, 98], [173, 220, 48], [253, 231, 37],
];
// Categories (status codes 0..4): ColorBrewer Set1 after a neutral grey for "ok".
const CATEGORIES = [
  [190, 190, 190], [255, 127, 0], [152, 78, 163], [228, 26, 28], [55, 126, 184],
  [77, 175, 74], [166, 86, 40], [247, 129, 191],
];
export const NAN_COLOR = [158, 158, 158];  // as the previews: points without a value
export const LUT_SIZE = 256;

function interpolate(anchors) {
  const lut = new Uint8Array(LUT_SIZE * 4);
  const last = anchors.length - 1;
  for (let i = 0; i < LUT_SIZE; i++) {
    const t = (i / (LUT_SIZE - 1)) * last;
    const k = Math.min(Math.floor(t), last - 1);
    const f = t - k;
    for (let c = 0; c < 3; c++) {
      lut[4 * i + c] = Math.round(anchors[k][c] * (1 - f) + anchors[k + 1][c] * f);
    }
    lut[4 * i + 3] = 255;
  }
  return lut;
}

export const DIVERGING = interpolate(RDBU_R);
export const SEQUENTIAL = interpolate(VIRIDIS);

/** Palette of `count` categories (cycled past the palette's length), RGBA bytes. */
export function categorical(count) {
  const lut = new Uint8Array(Math.max(count, 1) * 4);
  for (let i = 0; i < count; i++) {
    const [r, g, b] = CATEGORIES[i % CATEGORIES.length];
    lut.set([r, g, b, 255], 4 * i);
  }
  return lut;
}

/** CSS color of a lookup-table position t in [0, 1]. */
export function cssColor(lut, t) {
  const entries = lut.length / 4;
  const i = Math.min(entries - 1, Math.max(0, Math.round(t * (entries - 1))));
  return `rgb(${lut[4 * i]}, ${lut[4 * i + 1]}, ${lut[4 * i + 2]})`;
}
