/**
 * Run (live): the map as a heatmap or 3-D surface with the operating-point trail and the
 * active cell, the variance heatmap (log colour scale), measured vs predicted output and
 * residual (map estimators) or estimated vs true torque and its error (torque estimators),
 * the PE monitor λ_min(P), metric cards, progress, cancel/resume, and the versions timeline
 * (slider + play). Frames arrive over the live stream and are drawn at most 20 times a second
 * with Plotly.react (traces updated in place).
 */
import { api, estimators, showError } from "../api.js";
import { EVT, FRAME_INTERVAL_MS, RUN_ACTIVE, RUN_DONE, SEL, STORAGE, TRAIL_POINTS } from "../constants.js";
import {
  card, flatten, fmt, fmtDate, fmtDuration, fmtInt, h, icon, ICONS, metricLabel, pageHead, quantile, statusBadge, toast, withUnit,
} from "../dom.js";
import { exportMenu } from "../export-menu.js";
import { LiveStream } from "../live.js";
import { MapPlot, niceRange, SliceGroup } from "../map-plot.js";
import { axis, baseLayout, hasWebGL, purge, react, SERIES_COLORS, theme } from "../plot.js";
import { decimate, SeriesStore } from "../series.js";
import { VersionTimeline } from "../timeline.js";

export const title = "Run";

const SERIES_INTERVAL_MS = 250;
/** requestAnimationFrame ticks every ~16.7 ms: a frame due in under this much is drawn now, so
 * 20 frames/s are not rounded down to 15 by a tick that lands a hair early. */
const FRAME_SLACK_MS = 6;
/** Points of the dataset preview the colour range is taken from (min/max decimation keeps the peaks). */
const RANGE_PREVIEW_POINTS = 2000;
const VARIANCE_INTERVAL_MS = 100;
const META_REFRESH_MS = 2000;
const META_INTERVAL_MS = 400;
/** Points per drawn line (min/max per bucket): a 1000-px-wide plot shows no more. */
const LINE_POINTS = 1200;
/** Metrics shown by cards of their own (or not at all). */
const OWN_CARDS = new Set(["samples", "accepted", "run_s"]);

export async function mount(root, ctx) {
  const id = Number(ctx.params.id);
  const [run, catalog] = await Promise.all([api.get(`/api/runs/${id}`, { signal: ctx.signal }), estimators()]);
  const est = catalog.find((e) => e.name === run.estimator) ?? { name: run.estimator, title: run.estimator, kind: "" };
  const producesMap = run.produces_map ?? est.produces_map ?? true;
  // The colour scale of the run is fixed before the first frame is drawn: the measured
  // output's range (and the starting map's), the same on every load of the page.
  const wantsPreview = producesMap && Boolean(run.signals?.y);
  const [dataset, preview] = await Promise.all([
    api.get(`/api/datasets/${run.dataset_id}`, { signal: ctx.signal }).catch(() => null),
    wantsPreview
      ? api.get(`/api/datasets/${run.dataset_id}/preview`, { query: { points: RANGE_PREVIEW_POINTS }, signal: ctx.signal })
        .catch(() => null)
      : null,
  ]);
  window.dispatchEvent(new CustomEvent(EVT.currentRun, { detail: run }));

  const outputName = run.signals?.y ?? run.config?.output ?? "value";
  const outputUnit = dataset?.channels?.find((c) => c.name === outputName)?.unit ?? run.config?.output_unit ?? "";
  const s = {
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

  /* ---------- skeleton ---------- */
  const badge = h("span", { "data-run-status": "" }, statusBadge(run.status));
  const progressBar = h("span");
  const progress = h("div", { class: "progress", role: "progressbar", "aria-label": "Run progress", "aria-valuemin": "0",
    "aria-valuemax": "100", "data-run-progress": "" }, progressBar);
  const progressText = h("div", { class: "pct", "aria-live": "off" });
  const conn = h("span", { class: "legend-note", "data-connection": "" });
  const cancelBtn = h("button", { type: "button", class: "danger", "data-cancel": "", onclick: cancel }, icon(ICONS.stop), "Cancel");
  const resumeBtn = h("button", { type: "button", "data-resume": "", onclick: resume }, icon(ICONS.resume), "Resume");
  const exportEl = exportMenu(id, { versionId: () => timeline.viewing?.id ?? null, errorHost: root, signal: ctx.signal });
  const versionsLink = h("a", { class: "button", href: `/versions?a=${id}` }, icon(ICONS.versions), "Versions");
  const compareLink = h("a", { class: "button", href: `/compare?runs=${id}` }, icon(ICONS.compare), "Compare");
  const errorBanner = h("div", { class: "banner error", role: "alert", hidden: true, "data-run-error": "" });
  const metricsHost = h("div", { class: "metrics", "data-metrics": "" });

  root.append(
    pageHead({
      crumbs: [h("a", { href: "/compare" }, "Runs"), ` / #${id}`],
      title: run.name || `${est.title ?? est.name} on ${dataset?.name ?? `dataset #${run.dataset_id}`}`,
      sub: h("div", { class: "run-head-meta" }, badge, h("code", { class: "tag accent" }, run.estimator),
        dataset ? h("a", { href: `/datasets?id=${dataset.id}` }, dataset.name) : null,
        h("span", {}, `started ${fmtDate(run.started_at ?? run.created_at)}`),
        run.config?.pace && run.config.pace !== "max" ? h("span", {}, `pace ${run.config.pace}×`) : null,
        conn),
      actions: [cancelBtn, resumeBtn, compareLink, producesMap ? versionsLink : null, exportEl],
    }),
    errorBanner,
    h("div", { class: "run-progress" }, progress, progressText),
    metricsHost,
  );

  /* ---------- map + variance ---------- */
  const mapMode = localStorage.getItem(STORAGE.mapMode) === "surface" && hasWebGL() ? "surface" : "heatmap";
  const mapEl = h("div", { class: "plot map", "data-plot": "map", role: "img",
    "aria-label": `Map ${withUnit(outputName, outputUnit)} over ${(s.axes ?? []).map((a) => a.name).join(" and ")}` });
  const varEl = h("div", { class: "plot map", "data-plot": "variance", role: "img", "aria-label": "Cell variances, log colour scale" });
  // Live maps skip the cell gaps: cheaper frames (see MapPlot.drawBar for the colour bar).
  const slices = new SliceGroup();
  const mapPlot = new MapPlot(mapEl, { kind: "value", unit: outputUnit, label: outputName, mode: mapMode, gaps: false, slices });
  const varPlot = new MapPlot(varEl, { kind: "variance", unit: outputUnit, label: outputName, gaps: false, slices });
  mapPlot.setRange(runRange(run, preview));
  const modeButtons = ["heatmap", "surface"].map((m) =>
    h("button", { type: "button", "aria-pressed": String(m === mapMode), "data-map-mode": m, disabled: m === "surface" && !hasWebGL(),
      title: m === "surface" && !hasWebGL() ? "3-D needs WebGL, which this browser lacks" : null,
      onclick: () => {
        mapPlot.setMode(m);
        localStorage.setItem(STORAGE.mapMode, m);
        for (const b of modeButtons) b.setAttribute("aria-pressed", String(b.dataset.mapMode === m));
      } }, m === "heatmap" ? icon(ICONS.grid) : icon(ICONS.cube), m === "heatmap" ? "Heatmap" : "3-D"));

  /* ---------- timeline ---------- */
  const timeline = new VersionTimeline({
    runId: id,
    initialVersion: Number(ctx.query.get("version")) || null,
    onScrub: (version) => ctx.setQuery({ version: version?.id }),
    isLive: () => RUN_ACTIVE.has(s.run.status),
    onShow: (doc, _version, { quiet }) => drawMaps({ axes: doc.axes ?? s.axes, values: doc.values, variances: doc.variances,
      visits: doc.visits, trail: quiet ? s.trail : null, activeCell: null }),
    onLive: () => { s.dirtyMap = true; },
    onList: (versions) => {
      versionsLink.href = versions.length
        ? `/versions?a=${id}:${versions[0].id}&b=${id}:${versions.at(-1).id}` : `/versions?a=${id}`;
      renderMetrics();
    },
    baseMapName: () => `${s.run.name || s.run.estimator} #${id}`,
  });
  const refreshVersions = () => (producesMap ? timeline.refresh({ signal: ctx.signal }) : Promise.resolve());

  /* ---------- series ---------- */
  const isTorque = est.kind === "torque" || !producesMap;
  const seriesEl = h("div", { class: "plot medium", "data-plot": isTorque ? "torque" : "residual", role: "img",
    "aria-label": isTorque ? "Estimated and true torque with the error" : "Measured and predicted output with the residual" });
  const peEl = h("div", { class: "plot short", "data-plot": "pe", role: "img", "aria-label": "Smallest eigenvalue of P over time" });
  const gatesHost = h("div", { class: "gates", "data-gates": "" });
  const peCard = card({ title: "Persistent excitation", hint: "λ_min(P), log scale", body: peEl, cls: "pe-card" });
  peCard.hidden = !est.name.startsWith("adaptive");

  const seriesCard = card({ title: isTorque ? "Torque: estimated vs true" : "Measured vs predicted",
    hint: isTorque ? "error (true − estimated) below" : "residual below", body: seriesEl, bodyCls: "tight" });
  const setSeriesTitle = (text, hint) => {
    const h2 = seriesCard.querySelector(SEL.cardTitle);
    if (h2.firstChild.textContent !== text) h2.replaceChildren(text, h("span", { class: "hint" }, ` · ${hint}`));
  };
  const varCard = card({ title: "Variance", hint: "diag P, log colour scale", body: varEl, bodyCls: "tight" });
  const body = [];
  if (producesMap) {
    body.push(
      h("div", { class: "grid cols-2" },
        card({ title: "Map", hint: withUnit(outputName, outputUnit), actions: [timeline.note, h("div", { class: "seg", role: "group", "aria-label": "Map display" }, modeButtons)],
          body: mapEl, bodyCls: "tight" }),
        varCard),
      card({ title: "Versions", hint: "scrub or play the map's evolution", actions: [timeline.liveButton], body: timeline.el }),
    );
  }
  body.push(
    h("div", { class: isTorque ? "stack" : "grid side" },
      seriesCard,
      h("div", { class: "stack" },
        isTorque ? null : card({ title: "Rejected samples", hint: "by gate", body: gatesHost }),
        peCard,
        isTorque ? card({ title: "Rejected samples", hint: "by gate", body: gatesHost }) : null)),
  );
  root.append(h("div", { class: "stack", style: { marginTop: "16px" } }, body));

  /* ---------- state updates ---------- */
  function applyFull(msg) {
    if (msg.run) s.run = { ...s.run, ...msg.run };
    if (msg.axes) s.axes = msg.axes;
    if (msg.values) s.values = msg.values;
    s.variances = msg.variances ?? s.variances;
    s.visits = msg.visits ?? s.visits;
    s.activeCell = msg.active_cell ?? null;
    const pts = msg.trajectory?.points ?? [];
    s.trail = { x: pts.slice(-TRAIL_POINTS).map((p) => p[0]), y: pts.slice(-TRAIL_POINTS).map((p) => p[1]) };
    s.series.reset(msg.series ?? {});
    s.metrics = { ...s.metrics, ...(msg.metrics ?? {}), ...(msg.run?.metrics ?? {}) };
    s.sample = msg.sample ?? s.sample;
    s.nSamples = msg.n_samples ?? s.nSamples;
    s.progress = msg.run?.progress ?? (s.nSamples ? s.sample / s.nSamples : s.progress);
    s.dirtyMap = true;
    s.dirtySeries = true;
    renderMeta();
    if (RUN_DONE.has(s.run.status)) refreshVersions();
  }

  function applyDelta(msg) {
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

  function applyStatus(msg) {
    const before = s.run.status;
    s.run = { ...s.run, status: msg.status, error: msg.error ?? null, progress: msg.progress ?? s.run.progress };
    if (typeof msg.progress === "number") s.progress = msg.progress;
    renderMeta();
    if (before !== msg.status) {
      refreshRun();
      refreshVersions();
      if (RUN_DONE.has(msg.status)) loadStoredSeries();
      if (msg.status === "succeeded") toast(`Run #${id} finished.`);
      if (msg.status === "failed") toast(`Run #${id} failed: ${msg.error ?? "see the error above"}`, { error: true });
    }
  }

  /* ---------- rendering ---------- */
  let raf = 0;
  const loop = (now) => {
    raf = requestAnimationFrame(loop);
    // One plot per animation frame at most: a long series redraw never delays a map frame.
    if (s.dirtyMap && now - s.lastMap >= FRAME_INTERVAL_MS - FRAME_SLACK_MS) {
      s.lastMap = now;
      s.dirtyMap = false;
      const withVariance = now - s.lastVariance >= VARIANCE_INTERVAL_MS;
      if (withVariance) s.lastVariance = now;
      else s.dirtyVariance = true;
      if (!timeline.viewing) {
        drawMaps({ axes: s.axes, values: s.values, variances: s.variances, visits: s.visits, trail: s.trail, activeCell: s.activeCell },
          { variance: withVariance });
      }
      return;
    }
    if (s.dirtyVariance && now - s.lastVariance >= VARIANCE_INTERVAL_MS && !timeline.viewing) {
      s.lastVariance = now;
      s.dirtyVariance = false;
      if (s.axes && s.values) {
        drawMaps({ axes: s.axes, values: s.values, variances: s.variances, visits: s.visits, trail: s.trail, activeCell: s.activeCell },
          { map: false });
      }
      return;
    }
    if (s.dirtySeries && now - s.lastSeries >= SERIES_INTERVAL_MS) {
      s.lastSeries = now;
      s.dirtySeries = false;
      drawSeries();
      drawPe();
      return;
    }
    if (s.dirtyMeta && now - s.lastMeta >= META_INTERVAL_MS) {
      s.lastMeta = now;
      s.dirtyMeta = false;
      renderProgress();
      renderMetrics();
      renderGates();
    }
  };
  raf = requestAnimationFrame(loop);

  function drawMaps(frame, { variance = true, map = true } = {}) {
    if (!producesMap || !frame.axes || !frame.values) return;
    if (map) mapPlot.render(frame);
    if (!variance) return;
    if (frame.variances) varPlot.render(frame);
    else if (frame.visits) {
      // Observers without a covariance (LPV): the second map shows where the log has been.
      if (varPlot.kind !== "visits") {
        varPlot.kind = "visits";
        varPlot.range = null;
        varEl.setAttribute("aria-label", "Visits per cell");
        const h2 = varCard.querySelector(SEL.cardTitle);
        h2.replaceChildren("Visits", h("span", { class: "hint" }, " · samples weighted onto each cell (no covariance)"));
      }
      varPlot.render(frame);
    }
  }

  function drawSeries() {
    const t = theme();
    const data = [];
    let top;
    let bottom;
    // Estimators scored against a simulated truth (torque, the observers' compressor flow)
    // show estimate vs truth; table filters show measured vs predicted output.
    const truthMode = isTorque || (est.kind !== "table-filter" && s.series.has("truth"));
    if (truthMode) {
      const tt = s.series.pick("truth");
      const te = s.series.pick("estimate");
      const er = s.series.pick("error");
      const what = isTorque ? "torque" : (te ?? tt)?.name.replace(/_true$/, "") ?? "output";
      if (te) data.push(line(te, `estimated ${what}`, SERIES_COLORS[0], { width: 1.2 }));
      if (tt) data.push(line(tt, `true ${what}`, t.text, { width: 1.8 }));
      if (er) data.push({ ...line(er, "error", t.danger), yaxis: "y2" });
      top = withUnit(what, (te ?? tt)?.unit ?? (isTorque ? "N·m" : ""));
      bottom = withUnit("error", er?.unit ?? te?.unit ?? "");
      if (!isTorque) setSeriesTitle(`${what}: estimated vs true`, "error (true − estimated) below");
    } else {
      const me = s.series.pick("measured");
      const pr = s.series.pick("prediction");
      const re = s.series.pick("residual");
      if (me) data.push(line(me, "measured", t.text3, { width: 1.2 }));
      if (pr) data.push(line(pr, "predicted", SERIES_COLORS[0]));
      if (re) data.push({ ...line(re, "residual", SERIES_COLORS[1]), yaxis: "y2" });
      top = withUnit(outputName, (me ?? pr)?.unit ?? outputUnit);
      bottom = withUnit("residual", re?.unit ?? outputUnit);
    }
    if (!data.length) return;
    // Start-up transients (an observer settling) would flatten the rest: frame the bulk.
    const topRange = robustRange(data.filter((d) => d.yaxis !== "y2").flatMap((d) => d.y));
    const bottomRange = robustRange(data.filter((d) => d.yaxis === "y2").flatMap((d) => d.y));
    react(seriesEl, data, baseLayout({
      xaxis: axis("time [s]", { anchor: "y2" }),
      yaxis: axis(top, { domain: [0.4, 1], ...(topRange ? { range: topRange } : {}) }),
      yaxis2: axis(bottom, { domain: [0, 0.3], zeroline: true, ...(bottomRange ? { range: bottomRange } : {}) }),
      margin: { l: 62, r: 12, t: 26, b: 40 },
    }));
  }

  function drawPe() {
    const pe = s.series.pick("lambdaMin");
    if (!pe) return;
    peCard.hidden = false;
    react(peEl, [line(pe, "λ_min(P)", SERIES_COLORS[4])], baseLayout({
      xaxis: axis("time [s]"), yaxis: axis(withUnit("λ_min(P)", pe.unit), { type: "log", exponentformat: "e" }), showlegend: false,
      margin: { l: 62, r: 12, t: 10, b: 40 },
    }));
  }

  function renderProgress() {
    const pct = Math.max(0, Math.min(1, s.progress ?? 0)) * 100;
    progressBar.style.width = `${pct.toFixed(1)}%`;
    progress.setAttribute("aria-valuenow", pct.toFixed(0));
    progress.classList.toggle("ok", s.run.status === "succeeded");
    progress.classList.toggle("bad", s.run.status === "failed");
    const now = performance.now();
    if (now - s.rate.t > 1000) {
      const r = ((s.sample - s.rate.sample) * 1000) / (now - s.rate.t);
      s.rate = { t: now, sample: s.sample, value: RUN_ACTIVE.has(s.run.status) && r > 0 ? r : s.rate.value };
    }
    progressText.textContent = `${pct.toFixed(pct < 10 ? 1 : 0)} %` +
      (s.nSamples ? ` · ${fmtInt(s.sample)} / ${fmtInt(s.nSamples)} samples` : "") +
      (RUN_ACTIVE.has(s.run.status) && s.rate.value ? ` · ${fmtInt(s.rate.value)} samples/s` : "");
  }

  function renderMeta() {
    badge.replaceChildren(statusBadge(s.run.status));
    showConnection();
    cancelBtn.hidden = !RUN_ACTIVE.has(s.run.status);
    resumeBtn.hidden = !["interrupted", "cancelled"].includes(s.run.status);
    errorBanner.hidden = !s.run.error;
    errorBanner.textContent = s.run.error ? `Run failed: ${s.run.error}` : "";
    renderProgress();
    renderMetrics();
    renderGates();
  }

  function renderMetrics() {
    const cards = [];
    const metric = (k, v, unit = "", detail = "") => h("div", { class: "metric", dataset: { metric: k } },
      h("div", { class: "k" }, metricLabel(k)),
      h("div", { class: "v" }, v, unit ? h("span", { class: "u" }, unit) : null),
      detail ? h("div", { class: "d" }, detail) : null);
    const torqueUnit = s.series.pick("estimate")?.unit || "N·m";
    const unitOf = (k) => {
      if (isTorque && (k === "mae" || k === "sd")) return torqueUnit;
      if (k === "coverage") return "";
      if (/rmse|max_abs/.test(k)) return isTorque ? torqueUnit : outputUnit;
      return "";
    };
    const order = ["ise", "mae", "sd", "output_rmse", "rmse", "map_rmse", "max_abs_error", "mean_relative_error", "coverage"];
    const keys = Object.keys(s.metrics).sort((a, b) => (order.indexOf(a) + 1 || 99) - (order.indexOf(b) + 1 || 99));
    for (const k of keys) {
      const v = s.metrics[k];
      if (typeof v !== "number" || OWN_CARDS.has(k)) continue;
      cards.push(metric(k, k === "coverage" ? `${fmt(v * 100, 3)} %` : fmt(v), unitOf(k)));
    }
    const rejected = rejectedTotal(s.run.rejected ?? {});
    cards.push(metric("samples", fmtInt(s.sample || Math.round((s.progress ?? 0) * s.nSamples)), "", s.nSamples ? `of ${fmtInt(s.nSamples)}` : ""));
    if (producesMap) cards.push(metric("versions", fmtInt(Math.max(s.run.n_versions ?? 0, timeline.versions.length))));
    cards.push(metric("rejected", fmtInt(rejected), "", s.sample ? `${fmt((100 * rejected) / Math.max(1, s.sample), 3)} % of samples` : ""));
    if (typeof s.metrics.run_s === "number") cards.push(metric("compute time", fmtDuration(s.metrics.run_s)));
    else if (s.run.finished_at && s.run.started_at) {
      cards.push(metric("elapsed", fmtDuration((new Date(s.run.finished_at) - new Date(s.run.started_at)) / 1000)));
    }
    metricsHost.replaceChildren(...cards);
  }

  function renderGates() {
    const entries = Object.entries(s.run.rejected ?? {});
    if (!entries.length) {
      gatesHost.replaceChildren(h("p", { class: "help", style: { margin: 0 } }, "No samples rejected."));
      return;
    }
    const total = Math.max(1, s.sample || s.nSamples || 1);
    gatesHost.replaceChildren(...entries.sort((a, b) => b[1] - a[1]).map(([gate, n]) =>
      h("div", { class: "gate", dataset: { gate } },
        h("span", {}, gateLabel(gate)), h("b", {}, fmtInt(n)),
        h("div", { class: "bar", title: `${fmt((100 * n) / total, 3)} % of samples` },
          h("span", { style: { width: `${Math.min(100, (100 * n) / total)}%` } })))));
  }

  /* ---------- actions ---------- */
  async function cancel() {
    try {
      s.run = { ...s.run, ...(await api.post(`/api/runs/${id}/cancel`)) };
      renderMeta();
    } catch (err) {
      showError(root, err);
    }
  }

  async function resume() {
    try {
      s.run = { ...s.run, ...(await api.post(`/api/runs/${id}/resume`)) };
      renderMeta();
      restartStream();
    } catch (err) {
      showError(root, err);
    }
  }

  /** A finished run's stored series cover the whole log (the live ones may have gaps). */
  async function loadStoredSeries() {
    try {
      const body = await api.get(`/api/runs/${id}/series`, { query: { points: 4000 }, signal: ctx.signal });
      if (!body?.series || !Object.keys(body.series).length) return;
      s.series.reset(body.series, body.time);
      s.dirtySeries = true;
      s.dirtyMeta = true; // the metric cards take their units from the series
    } catch {
      /* keep the live series */
    }
  }

  async function refreshRun() {
    try {
      const fresh = await api.get(`/api/runs/${id}`, { signal: ctx.signal });
      s.run = { ...s.run, ...fresh };
      s.metrics = { ...s.metrics, ...(fresh.metrics ?? {}) };
      if (typeof fresh.progress === "number") s.progress = Math.max(s.progress ?? 0, fresh.progress);
      renderMeta();
    } catch {
      /* transient */
    }
  }

  /* ---------- stream ---------- */
  /** The live indicator: "● live" while a running run streams, the reconnect countdown, … */
  function showConnection() {
    const { state, detail } = s.connection;
    conn.dataset.state = state;
    const done = RUN_DONE.has(s.run.status);
    conn.textContent = state === "open" ? (done ? "" : "● live") : state === "reconnecting"
      ? `reconnecting in ${Math.round(detail.inMs / 100) / 10} s…` : state === "connecting" ? "connecting…" : "";
    conn.style.color = state === "open" ? "var(--ok)" : "var(--text-3)";
    if (state === "closed" && detail.reason) conn.textContent = `stream closed: ${detail.reason}`;
  }

  let stream = null;
  function restartStream() {
    stream?.close();
    stream = new LiveStream(`/api/runs/${id}/stream`, {
      onFull: applyFull,
      onDelta: applyDelta,
      onStatus: applyStatus,
      onConnection: (state, detail) => {
        s.connection = { state, detail };
        showConnection();
      },
    }).start();
  }
  restartStream();

  const metaTimer = setInterval(() => {
    if (RUN_ACTIVE.has(s.run.status)) {
      refreshRun();
      refreshVersions();
    }
  }, META_REFRESH_MS);

  renderMeta();
  refreshVersions();

  const onTheme = () => {
    s.dirtyMap = true;
    s.dirtySeries = true;
    timeline.reshow();
  };
  window.addEventListener(EVT.themeChange, onTheme);

  return () => {
    cancelAnimationFrame(raf);
    clearInterval(metaTimer);
    timeline.destroy();
    stream?.close();
    window.removeEventListener(EVT.themeChange, onTheme);
    mapPlot.destroy();
    varPlot.destroy();
    purge(seriesEl);
    purge(peEl);
  };
}

/**
 * The run's colour range: the measured output's span over the whole log together with the
 * starting map (θ0, typed values or a base map), on nice bounds; null when there is no
 * measured output (the plot then seeds from its first frame). Cells the filter extrapolates
 * beyond it saturate at the ends of the scale rather than rescale every frame.
 */
function runRange(run, preview) {
  const values = preview?.channels?.[run.signals?.y]?.values ?? [];
  const start = flatten([run.estimator_config?.theta0 ?? run.config?.theta0 ?? []]);
  let lo = Infinity;
  let hi = -Infinity;
  for (const v of [...values, ...start]) {
    if (typeof v !== "number" || !Number.isFinite(v)) continue;
    if (v < lo) lo = v;
    if (v > hi) hi = v;
  }
  return values.length && hi >= lo ? niceRange(lo, hi) : null;
}

function line(series, name, color, { width = 1.5, dash = "solid" } = {}) {
  const { x, y } = decimate(series.time, series.values, LINE_POINTS);
  return { type: "scatter", mode: "lines", x, y, name,
    line: { color, width, dash }, hovertemplate: `${name}: %{y:.4g} ${series.unit ?? ""}<br>t = %{x:.3f} s<extra></extra>` };
}

/** The 0.5–99.5 % span of the values, padded, or null when it adds nothing to autorange. */
function robustRange(values) {
  const finite = values.filter((v) => v !== null && Number.isFinite(v));
  if (finite.length < 50) return null;
  const lo = quantile(finite, 0.005);
  const hi = quantile(finite, 0.995);
  const min = Math.min(...finite);
  const max = Math.max(...finite);
  const span = hi - lo || Math.abs(hi) || 1;
  if (max - min < 1.6 * span) return null;
  return [lo - 0.15 * span, hi + 0.15 * span];
}

/**
 * Samples rejected in all: the accept mask (every service gate together), the innovation gate
 * and the samples before the sensor delay is filled; per-gate counts overlap within the mask.
 */
function rejectedTotal(rejected) {
  const keys = Object.keys(rejected);
  if (!keys.includes("mask")) return Object.values(rejected).reduce((a, b) => a + b, 0);
  return keys.filter((k) => !k.startsWith("gate:")).reduce((a, k) => a + rejected[k], 0);
}

function gateLabel(key) {
  const m = /^gate:([^:]+):(.+)$/.exec(key);
  if (m) return `${m[1]} gate · ${m[2]}`;
  return { mask: "all sample gates", innovation: "innovation gate", delay: "before the sensor delay" }[key] ?? key.replaceAll("_", " ");
}
