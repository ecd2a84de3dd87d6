/**
 * What the run page says about the run besides its plots: the head (status, estimator,
 * dataset, start, pace, the live indicator, cancel/resume, versions, compare, export), the
 * error banner, the progress bar with its sample rate, the metric cards and the samples
 * rejected by each gate.
 */
import { RUN_ACTIVE, RUN_DONE } from "../../constants.js";
import {
  fmt,
  fmtDate,
  fmtDuration,
  fmtInt,
  h,
  icon,
  ICONS,
  pageHead,
  statusBadge,
} from "../../dom.js";
import { exportMenu } from "../../export-menu.js";
import { fmtMetric, metricFormula, metricNameNode } from "../../metric-names.js";
import { SCOPE } from "../../scopes.js";

/** Metrics shown by cards of their own (or not at all). */
const OWN_CARDS = new Set(["samples", "accepted", "run_s"]);
/** The order of the metric cards (others after these). */
const METRIC_ORDER = [
  "ise",
  "mae",
  "sd",
  "output_rmse",
  "rmse",
  "map_rmse",
  "max_abs_error",
  "mean_relative_error",
  "coverage",
];

/**
 * The head, banner, progress and metric cards (`els`, in page order) and the rejected-samples
 * list (`gates`, placed by the page); render() brings them all up to date.
 */
export function runMeta(v, { onCancel, onResume }) {
  const { id, run, est, dataset, s } = v;
  const badge = h("span", { "data-run-status": "" }, statusBadge(run.status));
  const bar = h("span");
  const progress = h(
    "div",
    {
      class: "progress",
      role: "progressbar",
      "aria-label": "Run progress",
      "aria-valuemin": "0",
      "aria-valuemax": "100",
      "data-run-progress": "",
    },
    bar,
  );
  const progressText = h("div", { class: "pct", "aria-live": "off" });
  const conn = h("span", { class: "legend-note", "data-connection": "" });
  const cancelBtn = h(
    "button",
    {
      type: "button",
      class: "danger",
      "data-cancel": "",
      "data-needs": SCOPE.run,
      onclick: onCancel,
    },
    icon(ICONS.stop),
    "Cancel",
  );
  const resumeBtn = h(
    "button",
    { type: "button", "data-resume": "", "data-needs": SCOPE.run, onclick: onResume },
    icon(ICONS.resume),
    "Resume",
  );
  const exportEl = exportMenu(id, {
    versionId: () => v.timeline?.viewing?.id ?? null,
    errorHost: v.root,
    signal: v.ctx.signal,
    calibration: run.calibration ?? run.table?.calibration ?? null,
    producesMap: v.producesMap,
  });
  const versionsLink = h(
    "a",
    { class: "button", href: `/versions?a=${id}` },
    icon(ICONS.versions),
    "Versions",
  );
  const compareLink = h(
    "a",
    { class: "button", href: `/compare?runs=${id}` },
    icon(ICONS.compare),
    "Compare",
  );
  // "Run again…": New run filled with this run's dataset, estimator, signals, grid and config.
  const againLink = h(
    "a",
    { class: "button", href: `/runs/new?from=${id}`, "data-run-again": "" },
    icon(ICONS.play),
    "Run again…",
  );
  const errorBanner = h("div", {
    class: "banner error",
    role: "alert",
    hidden: true,
    "data-run-error": "",
  });
  const metricsHost = h("div", { class: "metrics", "data-metrics": "" });
  const gates = h("div", { class: "gates", "data-gates": "" });

  const head = pageHead({
    crumbs: [h("a", { href: "/compare" }, "Runs"), ` / #${id}`],
    title:
      run.name || `${est.title ?? est.name} on ${dataset?.name ?? `dataset #${run.dataset_id}`}`,
    sub: h(
      "div",
      { class: "run-head-meta" },
      badge,
      h("code", { class: "tag accent" }, run.estimator),
      dataset ? h("a", { href: `/datasets?id=${dataset.id}` }, dataset.name) : null,
      h("span", {}, `started ${fmtDate(run.started_at ?? run.created_at)}`),
      run.config?.pace && run.config.pace !== "max"
        ? h("span", {}, `pace ${run.config.pace}×`)
        : null,
      conn,
    ),
    actions: [
      cancelBtn,
      resumeBtn,
      againLink,
      compareLink,
      v.producesMap ? versionsLink : null,
      exportEl,
    ],
  });

  function renderProgress() {
    const pct = Math.max(0, Math.min(1, s.progress ?? 0)) * 100;
    bar.style.width = `${pct.toFixed(1)}%`;
    progress.setAttribute("aria-valuenow", pct.toFixed(0));
    progress.classList.toggle("ok", s.run.status === "succeeded");
    progress.classList.toggle("bad", s.run.status === "failed");
    const now = performance.now();
    if (now - s.rate.t > 1000) {
      const r = ((s.sample - s.rate.sample) * 1000) / (now - s.rate.t);
      s.rate = {
        t: now,
        sample: s.sample,
        value: RUN_ACTIVE.has(s.run.status) && r > 0 ? r : s.rate.value,
      };
    }
    progressText.textContent =
      `${pct.toFixed(pct < 10 ? 1 : 0)} %` +
      (s.nSamples ? ` · ${fmtInt(s.sample)} / ${fmtInt(s.nSamples)} samples` : "") +
      (RUN_ACTIVE.has(s.run.status) && s.rate.value ? ` · ${fmtInt(s.rate.value)} samples/s` : "");
  }

  /** The live indicator: "● live" while a running run streams, the reconnect countdown, … */
  function showConnection() {
    const { state, detail } = s.connection;
    conn.dataset.state = state;
    const done = RUN_DONE.has(s.run.status);
    let text = "";
    if (state === "open") text = done ? "" : "● live";
    else if (state === "reconnecting")
      text = `reconnecting in ${Math.round(detail.inMs / 100) / 10} s…`;
    else if (state === "connecting") text = "connecting…";
    conn.textContent = text;
    conn.style.color = state === "open" ? "var(--ok)" : "var(--text-3)";
    if (state === "closed" && detail.reason) conn.textContent = `stream closed: ${detail.reason}`;
  }

  const renderMetrics = () => metricsHost.replaceChildren(...metricCards(v));
  const renderGates = () => renderRejected(gates, s);

  function render() {
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

  /** The Versions button opens the first and last version (by number in the run) side by side. */
  function linkVersions(versions) {
    versionsLink.href = versions.length
      ? `/versions?a=${id}:${versions[0].number ?? 1}&b=${id}:${versions.at(-1).number ?? versions.length}`
      : `/versions?a=${id}`;
  }

  return {
    els: [
      head,
      errorBanner,
      h("div", { class: "run-progress" }, progress, progressText),
      metricsHost,
    ],
    gates,
    render,
    renderProgress,
    renderMetrics,
    renderGates,
    showConnection,
    linkVersions,
  };
}

/** A card per numeric metric (units from the output or the torque series), then the counts. */
function metricCards(v) {
  const { s, isTorque, outputUnit } = v;
  const metric = (k, value, unit = "", detail = "") =>
    h(
      "div",
      { class: "metric", dataset: { metric: k }, title: metricFormula(k, s.metrics) || null },
      h("div", { class: "k" }, metricNameNode(k)),
      h("div", { class: "v" }, value, unit ? h("span", { class: "u" }, unit) : null),
      detail ? h("div", { class: "d" }, detail) : null,
    );
  const torqueUnit = s.series.pick("estimate")?.unit || "N·m";
  const unitOf = (k) => {
    if (isTorque && (k === "mae" || k === "sd")) return torqueUnit;
    if (isTorque && k === "ise") return torqueUnit === "N·m" ? "N²·m²·s" : `(${torqueUnit})²·s`;
    if (k === "coverage") return "";
    if (isTorque && /rmse|max_abs/.test(k)) return torqueUnit;
    // The measured output's errors are in its unit (the residual's): for the EKF's map q
    // (relative) that is the MAF's kg/s, not the map's unit.
    if (
      /^output_rmse$|^holdout:.*(rmse|mae|max_abs_error)$|^nis:innovation_mean$|^residual:(mean|rms)$/.test(
        k,
      )
    )
      return s.series.pick("residual")?.unit || outputUnit || "";
    if (/rmse|max_abs/.test(k)) {
      // The map's errors; an observer without an output channel scores its own estimate.
      return outputUnit || s.series.pick("estimate")?.unit || "";
    }
    return "";
  };
  const rank = (k) => METRIC_ORDER.indexOf(k) + 1 || 99;
  const cards = [];
  for (const k of Object.keys(s.metrics).sort((a, b) => rank(a) - rank(b))) {
    const value = s.metrics[k];
    if (typeof value !== "number" || OWN_CARDS.has(k) || k.startsWith("nis:mean_band")) continue;
    // NIS (docs/tuning.md): its mean is read against the 95 % band of its χ² distribution,
    // and a mean outside it says which way the noise settings are off.
    let band = "";
    if (k === "nis:mean" && "nis:mean_band_low" in s.metrics) {
      const [low, high] = [s.metrics["nis:mean_band_low"], s.metrics["nis:mean_band_high"]];
      band = `95 % band ${fmt(low)}–${fmt(high)}`;
      const verdict =
        value > high
          ? "above: overconfident (σw or σv too small)"
          : value < low
            ? "below: too cautious (σw, σv or σf too large)"
            : "";
      if (verdict)
        band = h("span", { class: "out-of-band", "data-nis-verdict": "" }, `${band}, ${verdict}`);
    }
    cards.push(metric(k, fmtMetric(k, value), unitOf(k), band));
  }
  const rejected = rejectedTotal(s.run.rejected ?? {});
  const samples = s.sample || Math.round((s.progress ?? 0) * s.nSamples);
  cards.push(metric("samples", fmtInt(samples), "", s.nSamples ? `of ${fmtInt(s.nSamples)}` : ""));
  if (v.producesMap) {
    const versions = Math.max(s.run.n_versions ?? 0, v.timeline?.versions.length ?? 0);
    cards.push(metric("versions", fmtInt(versions)));
  }
  const share = s.sample ? `${fmt((100 * rejected) / Math.max(1, s.sample), 3)} % of samples` : "";
  cards.push(metric("rejected", fmtInt(rejected), "", share));
  if (typeof s.metrics.run_s === "number")
    cards.push(metric("compute time", fmtDuration(s.metrics.run_s)));
  else if (s.run.finished_at && s.run.started_at) {
    const elapsed = (new Date(s.run.finished_at) - new Date(s.run.started_at)) / 1000;
    cards.push(metric("elapsed", fmtDuration(elapsed)));
  }
  return cards;
}

/**
 * Samples rejected, by reason, so the rows add up: the estimator's reasons (one status per
 * sample, most first) sum to the total; the sample gates' row is split per gate (in the
 * run's gate order), a sample failing several gates counted once, under the first.
 */
function renderRejected(host, s) {
  const rejected = s.run.rejected ?? {};
  const entries = Object.entries(rejected);
  const none = !entries.some(([k, n]) => n > 0 || k.startsWith("gate:"));
  if (none) {
    host.replaceChildren(h("p", { class: "help", style: { margin: 0 } }, "No samples rejected."));
    return;
  }
  const samples = Math.max(1, s.sample || s.nSamples || 1);
  const gates = entries.filter(([k]) => k.startsWith("gate:"));
  const own = entries.filter(([k]) => !k.startsWith("gate:"));
  const split = own.some(([k]) => k === "mask") && gates.length > 0;
  const row = (key, n, { sub = false, title = "" } = {}) =>
    h(
      "div",
      { class: `gate${sub ? " sub" : ""}`, dataset: { gate: key }, title: title || null },
      h("span", {}, gateLabel(key)),
      h("b", {}, fmtInt(n)),
      h(
        "div",
        { class: "bar", title: `${fmt((100 * n) / samples, 3)} % of samples` },
        h("span", { style: { width: `${Math.min(100, (100 * n) / samples)}%` } }),
      ),
    );
  const firstGate = !gates.length
    ? ""
    : "A sample that fails several gates is counted once, under the first of them in the " +
      "run's gate list" +
      (rejected.delay
        ? "; with a sensor delay, a step is gated when its measurement or its operating-point " +
          "sample is."
        : ".");
  const rows = [];
  const top = split ? own : [...own, ...gates];
  for (const [key, n] of top.sort((a, b) => b[1] - a[1])) {
    if (!n && !(key === "mask" && split) && !key.startsWith("gate:")) continue;
    const isGate = key.startsWith("gate:") || key === "mask";
    rows.push(row(key, n, { title: isGate ? firstGate : "" }));
    if (key !== "mask" || !split) continue;
    for (const [gate, m] of gates) rows.push(row(gate, m, { sub: true, title: firstGate }));
    const rest = n - gates.reduce((a, [, m]) => a + m, 0);
    if (rest > 0) rows.push(row("other", rest, { sub: true, title: "Masked; no gate claims it." }));
  }
  rows.push(
    h(
      "div",
      {
        class: "gate total",
        dataset: { gate: "total" },
        title: `The sum of the reasons above (each sample counted once). ${firstGate}`.trim(),
      },
      h("span", {}, "Total rejected"),
      h("b", {}, fmtInt(rejectedTotal(rejected))),
    ),
  );
  host.replaceChildren(...rows);
}

/**
 * Samples rejected in all: the estimator's reasons (the accept mask of every sample gate
 * together, the innovation gate, the samples before the sensor delay is filled), which are
 * disjoint; the per-gate counts split the mask. Without a mask count, the gates' sum.
 */
function rejectedTotal(rejected) {
  const keys = Object.keys(rejected);
  if (!keys.includes("mask")) return Object.values(rejected).reduce((a, b) => a + b, 0);
  return keys.filter((k) => !k.startsWith("gate:")).reduce((a, k) => a + rejected[k], 0);
}

function gateLabel(key) {
  const m = /^gate:([^:]+):(.+)$/.exec(key);
  if (m) return `${m[1]} gate · ${m[2]}`;
  const named = {
    mask: "sample gates",
    innovation: "innovation gate",
    delay: "before the sensor delay",
  };
  return named[key] ?? key.replaceAll("_", " ");
}
