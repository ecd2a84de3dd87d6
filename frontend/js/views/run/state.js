/**
 * The live state of a run's page and how stream messages update it: a "full" message (on
 * connect) replaces it, a "delta" adds the latest samples, a "status" moves the run along.
 * The dirty flags tell the render loop (frames.js) what to redraw.
 */
import { TRAIL_POINTS } from "../../constants.js";
import { SeriesStore } from "../../series.js";

export function runState(run, dataset) {
  return {
    run,
    axes: run.table?.axes ?? null,
    values: null,
    variances: null,
    visits: null,
    activeCell: null,
    trail: { x: [], y: [] },
    series: new SeriesStore(),
    metrics: { ...(run.metrics ?? {}) },
    sample: 0,
    nSamples: dataset?.rows ?? 0,
    progress: run.progress ?? 0,
    dirtyMap: false,
    dirtySeries: false,
    lastMap: 0,
    lastSeries: 0,
    lastVariance: 0,
    dirtyVariance: false,
    dirtyMeta: false,
    lastMeta: 0,
    rate: { t: performance.now(), sample: 0, value: null },
    connection: { state: "connecting", detail: {} },
  };
}

/** The live map frame of the state (what MapPlot.render draws). */
export function liveFrame(s) {
  return {
    axes: s.axes,
    values: s.values,
    variances: s.variances,
    visits: s.visits,
    trail: s.trail,
    activeCell: s.activeCell,
  };
}

/** The whole state from a "full" message: the map, the last trail points, the series. */
export function applyFull(s, msg) {
  if (msg.run) s.run = { ...s.run, ...msg.run };
  if (msg.axes) s.axes = msg.axes;
  if (msg.values) s.values = msg.values;
  s.variances = msg.variances ?? s.variances;
  s.visits = msg.visits ?? s.visits;
  s.activeCell = msg.active_cell ?? null;
  const pts = (msg.trajectory?.points ?? []).slice(-TRAIL_POINTS);
  s.trail = { x: pts.map((p) => p[0]), y: pts.map((p) => p[1]) };
  s.series.reset(msg.series ?? {});
  s.metrics = { ...s.metrics, ...(msg.metrics ?? {}), ...(msg.run?.metrics ?? {}) };
  s.sample = msg.sample ?? s.sample;
  s.nSamples = msg.n_samples ?? s.nSamples;
  s.progress = msg.run?.progress ?? (s.nSamples ? s.sample / s.nSamples : s.progress);
  s.dirtyMap = true;
  s.dirtySeries = true;
}

/** What changed since the last message; the trail keeps its last TRAIL_POINTS points. */
export function applyDelta(s, msg) {
  if (msg.values) s.values = msg.values;
  if (msg.variances) s.variances = msg.variances;
  if (msg.visits) s.visits = msg.visits;
  if ("active_cell" in msg) s.activeCell = msg.active_cell;
  const pts = msg.trajectory?.points ?? [];
  if (pts.length) {
    s.trail.x.push(...pts.map((p) => p[0]));
    s.trail.y.push(...pts.map((p) => p[1]));
    if (s.trail.x.length > TRAIL_POINTS) {
      s.trail.x = s.trail.x.slice(-TRAIL_POINTS);
      s.trail.y = s.trail.y.slice(-TRAIL_POINTS);
    }
  }
  if (msg.series) {
    s.series.append(msg.series);
    s.dirtySeries = true;
  }
  if (msg.metrics) s.metrics = { ...s.metrics, ...msg.metrics };
  if (msg.rejected) s.run = { ...s.run, rejected: msg.rejected };
  if (typeof msg.sample === "number") s.sample = msg.sample;
  if (typeof msg.progress === "number") s.progress = msg.progress;
  s.dirtyMap = true;
  s.dirtyMeta = true;
}

/** The run's new status (and error, progress); returns the status it had before. */
export function applyStatus(s, msg) {
  const before = s.run.status;
  s.run = {
    ...s.run,
    status: msg.status,
    error: msg.error ?? null,
    progress: msg.progress ?? s.run.progress,
  };
  if (typeof msg.progress === "number") s.progress = msg.progress;
  return before;
}

/** A fresh GET of the run merged in (progress never goes back). */
export function applyRun(s, fresh) {
  s.run = { ...s.run, ...fresh };
  s.metrics = { ...s.metrics, ...(fresh.metrics ?? {}) };
  if (typeof fresh.progress === "number") s.progress = Math.max(s.progress ?? 0, fresh.progress);
}
