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
  metricLabel,
  pageHead,
  statusBadge,
} from "../../dom.js";
import { exportMenu } from "../../export-menu.js";
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
    actions: [cancelBtn, resumeBtn, compareLink, v.producesMap ? versionsLink : null, exportEl],
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

  /** The Versions button opens the first and last version side by side. */
  function linkVersions(versions) {
    versionsLink.href = versions.length
      ? `/versions?a=${id}:${versions[0].id}&b=${id}:${versions.at(-1).id}`
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
      { class: "metric", dataset: { metric: k } },
      h("div", { class: "k" }, metricLabel(k)),
      h("div", { class: "v" }, value, unit ? h("span", { class: "u" }, unit) : null),
      detail ? h("div", { class: "d" }, detail) : null,
    );
  const torqueUnit = s.series.pick("estimate")?.unit || "N·m";
  const unitOf = (k) => {
    if (isTorque && (k === "mae" || k === "sd")) return torqueUnit;
    if (k === "coverage") return "";
    if (/rmse|max_abs|^holdout:.*mae$|^nis:innovation_mean$/.test(k)) {
      return isTorque ? torqueUnit : outputUnit;
    }
    return "";
  };
  const rank = (k) => METRIC_ORDER.indexOf(k) + 1 || 99;
  const cards = [];
  for (const k of Object.keys(s.metrics).sort((a, b) => rank(a) - rank(b))) {
    const value = s.metrics[k];
    if (typeof value !== "number" || OWN_CARDS.has(k) || k.startsWith("nis:mean_band")) continue;
    const percent = k === "coverage" || k === "nis:in_band";
    // NIS (docs/tuning.md): its mean is read against the 95 % band of its χ² distribution.
    const band =
      k === "nis:mean" && "nis:mean_band_low" in s.metrics
        ? `95 % band ${fmt(s.metrics["nis:mean_band_low"])}–${fmt(s.metrics["nis:mean_band_high"])}`
        : "";
    cards.push(metric(k, percent ? `${fmt(value * 100, 3)} %` : fmt(value), unitOf(k), band));
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

/** Samples rejected per gate, most first, each with its share of the samples as a bar. */
function renderRejected(host, s) {
  const entries = Object.entries(s.run.rejected ?? {});
  if (!entries.length) {
    host.replaceChildren(h("p", { class: "help", style: { margin: 0 } }, "No samples rejected."));
    return;
  }
  const total = Math.max(1, s.sample || s.nSamples || 1);
  host.replaceChildren(
    ...entries
      .sort((a, b) => b[1] - a[1])
      .map(([gate, n]) =>
        h(
          "div",
          { class: "gate", dataset: { gate } },
          h("span", {}, gateLabel(gate)),
          h("b", {}, fmtInt(n)),
          h(
            "div",
            { class: "bar", title: `${fmt((100 * n) / total, 3)} % of samples` },
            h("span", { style: { width: `${Math.min(100, (100 * n) / total)}%` } }),
          ),
        ),
      ),
  );
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
  const named = {
    mask: "all sample gates",
    innovation: "innovation gate",
    delay: "before the sensor delay",
  };
  return named[key] ?? key.replaceAll("_", " ");
}
