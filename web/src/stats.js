// Statistics of a field for its color limits and histogram. Limits follow the PNG previews
// (curvature.preview.color_limits): the 2nd to 98th percentile of the finite values,
// symmetric around 0 for a diverging field.

export const PERCENTILES = [2, 98];
export const HISTOGRAM_BINS = 120;

/** The finite values of `values`, sorted ascending (a new Float32Array). */
export function finiteSorted(values) {
  let count = 0;
  for (let i = 0; i < values.length; i++) if (Number.isFinite(values[i])) count++;
  const out = new Float32Array(count);
  let j = 0;
  for (let i = 0; i < values.length; i++) if (Number.isFinite(values[i])) out[j++] = values[i];
  return out.sort();
}

/** Percentile q (0..100) of sorted values, linearly interpolated (numpy's default). */
export function percentile(sorted, q) {
  if (!sorted.length) return NaN;
  const pos = (q / 100) * (sorted.length - 1);
  const lo = Math.floor(pos);
  const hi = Math.min(lo + 1, sorted.length - 1);
  return sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo);
}

/**
 * Default color limits of a field.
 * @param {Float32Array} sorted finite values, ascending
 * @param {object} entry the field's listing entry (scale, limits, categories)
 * @returns {{vmin: number, vmax: number, mode: string}} mode: diverging | sequential |
 *   categorical
 */
export function defaultLimits(sorted, entry) {
  if (entry.scale === "categorical") {
    const codes = Object.keys(entry.categories || {}).map(Number);
    const top = Math.max(codes.length ? Math.max(...codes) : 0,
      sorted.length ? sorted[sorted.length - 1] : 0);
    return { vmin: -0.5, vmax: top + 0.5, mode: "categorical" };
  }
  if (entry.limits) return { vmin: entry.limits[0], vmax: entry.limits[1], mode: entry.scale };
  if (!sorted.length) return { vmin: -1, vmax: 1, mode: "diverging" };
  const lo = percentile(sorted, PERCENTILES[0]);
  const hi = percentile(sorted, PERCENTILES[1]);
  const diverging = entry.scale === "diverging" || (entry.scale === "auto" && lo < 0 && hi > 0);
  if (diverging) {
    const half = Math.max(Math.abs(lo), Math.abs(hi)) || 1;
    return { vmin: -half, vmax: half, mode: "diverging" };
  }
  if (hi - lo <= 1e-12 * Math.max(Math.abs(lo), Math.abs(hi), 1e-300)) {
    const pad = lo !== 0 ? 0.05 * Math.abs(lo) : 1;
    return { vmin: lo - pad, vmax: hi + pad, mode: "sequential" };
  }
  return { vmin: lo, vmax: hi, mode: "sequential" };
}

/** The value range a histogram shows: the 0.5th to 99.5th percentile widened by a tenth,
 * and always holding the limits. */
export function histogramDomain(sorted, limits) {
  let lo = limits.vmin;
  let hi = limits.vmax;
  if (sorted.length) {
    const a = percentile(sorted, 0.5);
    const b = percentile(sorted, 99.5);
    const pad = 0.1 * (b - a);
    lo = Math.min(lo, Math.max(sorted[0], a - pad));
    hi = Math.max(hi, Math.min(sorted[sorted.length - 1], b + pad));
  }
  if (!(hi > lo)) hi = lo + 1;
  return [lo, hi];
}

/** Counts of sorted values in `bins` equal bins over [lo, hi] (values outside ignored). */
export function histogram(sorted, lo, hi, bins = HISTOGRAM_BINS) {
  const counts = new Uint32Array(bins);
  const scale = bins / (hi - lo);
  for (let i = 0; i < sorted.length; i++) {
    const v = sorted[i];
    if (v < lo || v > hi) continue;
    counts[Math.min(bins - 1, Math.floor((v - lo) * scale))]++;
  }
  return counts;
}

/** Median of a list of numbers. */
export function median(list) {
  const s = [...list].sort((a, b) => a - b);
  const m = s.length >> 1;
  return s.length % 2 ? s[m] : (s[m - 1] + s[m]) / 2;
}
