/**
 * Run (live): the map as a heatmap or 3-D surface with the operating-point trail and the
 * active cell, the variance heatmap (log colour scale), measured vs predicted output and
 * residual (map estimators) or estimated vs true torque and its error (torque estimators),
 * the PE monitor λ_min(P), metric cards, progress, cancel/resume, and the versions timeline
 * (slider + play). Frames arrive over the live stream and are drawn at most 20 times a second
 * with Plotly.react (traces updated in place).
 *
 * The parts share `v` (the run, its estimator and dataset, the live state `v.s`): state.js
 * (stream messages → state), frames.js (the render loop), maps.js (maps and timeline),
 * series.js, meta.js (head, progress, metric cards, rejected samples).
 */
import { api, estimators, showError } from "../../api.js";
import { EVT, RUN_ACTIVE, RUN_DONE } from "../../constants.js";
import { card, h, toast } from "../../dom.js";
import { LiveStream } from "../../live.js";
import { poll } from "../../poll.js";
import { runEdit } from "./edit.js";
import { startRenderLoop } from "./frames.js";
import { runMaps, runTimeline } from "./maps.js";
import { runMeta } from "./meta.js";
import { runSeries } from "./series.js";
import { mapQuantity } from "./trust-maps.js";
import { applyDelta, applyFull, applyRun, applyStatus, runState } from "./state.js";

export const title = "Run";

/** Points of the dataset preview the colour range is taken from (min/max decimation keeps the peaks). */
const RANGE_PREVIEW_POINTS = 2000;
/** While the run goes, the run itself (metrics, progress) and its versions are fetched this often. */
const META_REFRESH_MS = 2000;

export async function mount(root, ctx) {
  const id = Number(ctx.params.id);
  const [run, catalog] = await Promise.all([
    api.get(`/api/runs/${id}`, { signal: ctx.signal }),
    estimators(),
  ]);
  const est = catalog.find((e) => e.name === run.estimator) ?? {
    name: run.estimator,
    title: run.estimator,
    kind: "",
  };
  const producesMap = run.produces_map ?? est.produces_map ?? true;
  // The colour scale of the run is fixed before the first frame is drawn: the measured
  // output's range (and the starting map's), the same on every load of the page.
  const wantsPreview = producesMap && Boolean(run.signals?.y);
  const previewQuery = { query: { points: RANGE_PREVIEW_POINTS }, signal: ctx.signal };
  const [dataset, preview] = await Promise.all([
    api.get(`/api/datasets/${run.dataset_id}`, { signal: ctx.signal }).catch(() => null),
    wantsPreview
      ? api.get(`/api/datasets/${run.dataset_id}/preview`, previewQuery).catch(() => null)
      : null,
  ]);
  window.dispatchEvent(new CustomEvent(EVT.currentRun, { detail: run }));

  // Map observers have no output column: their map quantity names the values (trust-maps.js).
  const quantity = mapQuantity(run);
  const outputName = run.signals?.y ?? run.config?.output ?? quantity?.name ?? "value";
  const outputUnit =
    dataset?.channels?.find((c) => c.name === outputName)?.unit ??
    run.config?.output_unit ??
    quantity?.unit ??
    "";
  const v = {
    id,
    ctx,
    root,
    run,
    est,
    dataset,
    producesMap,
    // Torque views (θ̂, running ISE, the 5–30 s scoring window) are the torque estimators'
    // alone: the joint EKF without a map plots its own estimate against the truth.
    isTorque: est.kind === "torque",
    outputName,
    outputUnit,
    s: runState(run, dataset),
  };
  const { s } = v;

  /* ---------- actions ---------- */
  const refreshVersions = () =>
    producesMap ? v.timeline.refresh({ signal: ctx.signal }) : Promise.resolve();

  async function refreshRun() {
    try {
      applyRun(s, await api.get(`/api/runs/${id}`, { signal: ctx.signal }));
      v.meta.render();
      whenDone();
    } catch {
      /* transient */
    }
  }

  /* Once the run is done its stored series replace the live ones, whichever of the status
   * frame, a full frame or the poll of the run says so first (the poll may set the status
   * before the frame comes, and the frame then changes nothing). */
  let storedSeries = false;
  function whenDone() {
    if (RUN_ACTIVE.has(s.run.status)) storedSeries = false; // resumed: load them again at its end
    if (storedSeries || !RUN_DONE.has(s.run.status)) return;
    storedSeries = true;
    loadStoredSeries();
  }

  /** A finished run's stored series cover the whole log (the live ones may have gaps). */
  async function loadStoredSeries() {
    try {
      const body = await api.get(`/api/runs/${id}/series`, {
        query: { points: 4000 },
        signal: ctx.signal,
      });
      if (!body?.series || !Object.keys(body.series).length) return;
      s.series.reset(body.series, body.time);
      s.dirtySeries = true;
      s.dirtyMeta = true; // the metric cards take their units from the series
    } catch {
      /* keep the live series */
    }
  }

  /** POST cancel or resume; the answer is the run as it is now. */
  const act = (verb, then) => async () => {
    try {
      s.run = { ...s.run, ...(await api.post(`/api/runs/${id}/${verb}`)) };
      v.meta.render();
      then?.();
    } catch (err) {
      showError(root, err);
    }
  };

  /* ---------- layout ---------- */
  v.meta = runMeta(v, { onCancel: act("cancel"), onResume: act("resume", () => restartStream()) });
  root.append(...v.meta.els);
  v.maps = runMaps(v, preview);
  v.maps.loadTruth(ctx.signal);
  v.timeline = runTimeline(v);
  v.series = runSeries(v);
  root.append(h("div", { class: "stack", style: { marginTop: "16px" } }, layout(v)));
  if (producesMap) v.edit = runEdit(v); // its card goes under the versions timeline

  /* ---------- stream ---------- */
  const onFull = (msg) => {
    applyFull(s, msg);
    v.meta.render();
    if (RUN_DONE.has(s.run.status)) refreshVersions();
    whenDone();
  };
  const onStatus = (msg) => {
    const before = applyStatus(s, msg);
    v.meta.render();
    whenDone();
    if (before === msg.status) return;
    refreshRun();
    refreshVersions();
    if (msg.status === "succeeded") toast(`Run #${id} finished.`);
    if (msg.status === "failed")
      toast(`Run #${id} failed: ${msg.error ?? "see the error above"}`, { error: true });
  };
  let stream = null;
  function restartStream() {
    stream?.close();
    stream = new LiveStream(`/api/runs/${id}/stream`, {
      onFull,
      onDelta: (msg) => applyDelta(s, msg),
      onStatus,
      onConnection: (state, detail) => {
        s.connection = { state, detail };
        v.meta.showConnection();
      },
    }).start();
  }

  const stopLoop = startRenderLoop(v);
  restartStream();
  poll(
    ctx.signal,
    () => {
      if (RUN_ACTIVE.has(s.run.status)) {
        refreshRun();
        refreshVersions();
      }
      return true;
    },
    META_REFRESH_MS,
    { now: false },
  );
  v.meta.render();
  refreshVersions();

  const onTheme = () => {
    s.dirtyMap = true;
    s.dirtySeries = true;
    v.timeline.reshow();
  };
  window.addEventListener(EVT.themeChange, onTheme);

  return () => {
    stopLoop();
    v.timeline.destroy();
    stream?.close();
    window.removeEventListener(EVT.themeChange, onTheme);
    v.maps.destroy();
    v.series.destroy();
  };
}

/** Maps, variance and versions (map estimators), then the series beside the rejected samples. */
function layout(v) {
  const { maps, timeline, series, meta, isTorque } = v;
  const body = [];
  if (v.producesMap) {
    body.push(
      h("div", { class: "grid cols-2" }, maps.mapCard(timeline.note), maps.varCard),
      h("div", { class: "grid cols-2", "data-trust-maps": "" }, maps.hitsCard, maps.errorCard),
      card({
        title: "Versions",
        hint: "scrub or play the map's evolution",
        actions: [timeline.liveButton],
        body: timeline.el,
      }),
    );
  }
  const rejected = card({ title: "Rejected samples", hint: "by reason", body: meta.gates });
  body.push(
    h(
      "div",
      { class: isTorque ? "stack" : "grid side" },
      series.seriesCard,
      isTorque ? h("div", { class: "grid cols-2" }, series.thetaCard, series.iseCard) : null,
      h(
        "div",
        { class: "stack" },
        isTorque ? null : rejected,
        series.peCard,
        isTorque ? rejected : null,
      ),
    ),
  );
  return body;
}
