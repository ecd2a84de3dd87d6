/**
 * The run's time series: measured vs predicted output with the residual (table filters), or
 * estimate vs truth with the error (torque estimators, observers scored against a simulated
 * truth); and the persistent-excitation monitor λ_min(P) of the adaptive estimators.
 */
import { SEL } from "../../constants.js";
import { card, h, quantile, withUnit } from "../../dom.js";
import { axis, baseLayout, purge, react, SERIES_COLORS, theme } from "../../plot.js";
import { decimate } from "../../series.js";
import { torqueViews, windowShape } from "./torque.js";

/** Points per drawn line (min/max per bucket): a 1000-px-wide plot shows no more. */
const LINE_POINTS = 1200;
/** The legend name of the rejected samples' markers (what tests look for). */
export const REJECTED_TRACE = "rejected (gates)";

/** The series and PE cards; draw() redraws both from `v.s.series`. */
export function runSeries(v) {
  const { est, isTorque } = v;
  const seriesEl = h("div", {
    class: "plot medium",
    "data-plot": isTorque ? "torque" : "residual",
    role: "img",
    "aria-label": isTorque
      ? "Estimated and true torque with the error"
      : "Measured and predicted output with the residual",
  });
  const peEl = h("div", {
    class: "plot short",
    "data-plot": "pe",
    role: "img",
    "aria-label": "Smallest eigenvalue of P over time",
  });
  const peCard = card({
    title: "Persistent excitation",
    hint: "λ_min(P), log scale",
    body: peEl,
    cls: "pe-card",
  });
  peCard.hidden = !est.name.startsWith("adaptive");
  const seriesCard = card({
    title: isTorque ? "Torque: estimated vs true" : "Measured vs predicted",
    hint: isTorque ? "error (true − estimated) below" : "residual below",
    body: seriesEl,
    bodyCls: "tight",
  });
  // Torque estimators: θ̂ (adaptive laws), running ISE, the scoring window (torque.js).
  const torque = isTorque ? torqueViews(v) : null;
  const setTitle = (text, hint) => {
    const h2 = seriesCard.querySelector(SEL.cardTitle);
    if (h2.firstChild.textContent !== text)
      h2.replaceChildren(text, h("span", { class: "hint" }, ` · ${hint}`));
  };

  function drawSeries() {
    const { data, top, bottom } = traces(v, setTitle);
    if (!data.length) return;
    // Start-up transients (an observer settling) would flatten the rest: frame the bulk.
    const topRange = robustRange(data.filter((d) => d.yaxis !== "y2").flatMap((d) => d.y));
    // The rejection markers sit on zero: they say when, not how much.
    const bottomRange = robustRange(
      data.filter((d) => d.yaxis === "y2" && d.mode === "lines").flatMap((d) => d.y),
    );
    react(
      seriesEl,
      data,
      baseLayout({
        xaxis: axis("time [s]", { anchor: "y2" }),
        yaxis: axis(top, { domain: [0.4, 1], ...(topRange ? { range: topRange } : {}) }),
        yaxis2: axis(bottom, {
          domain: [0, 0.3],
          zeroline: true,
          ...(bottomRange ? { range: bottomRange } : {}),
        }),
        margin: { l: 62, r: 12, t: 26, b: 40 },
        ...(torque ? { shapes: windowShape(torque.window()) } : {}),
      }),
    );
  }

  function drawPe() {
    const pe = v.s.series.pick("lambdaMin");
    if (!pe) return;
    peCard.hidden = false;
    react(
      peEl,
      [line(pe, "λ_min(P)", SERIES_COLORS[4])],
      baseLayout({
        xaxis: axis("time [s]"),
        yaxis: axis(withUnit("λ_min(P)", pe.unit), { type: "log", exponentformat: "e" }),
        showlegend: false,
        margin: { l: 62, r: 12, t: 10, b: 40 },
      }),
    );
  }

  return {
    seriesCard,
    peCard,
    /** Torque estimators' θ̂ and running-ISE cards (null for the others). */
    thetaCard: torque?.thetaCard ?? null,
    iseCard: torque?.iseCard ?? null,
    draw: () => {
      drawSeries();
      drawPe();
      torque?.draw(torque.window());
    },
    destroy: () => {
      purge(seriesEl);
      purge(peEl);
      torque?.destroy();
    },
  };
}

/** The traces of the series plot (upper: the signals, lower on y2: their error) and axis titles. */
function traces(v, setTitle) {
  const { s, est, isTorque, outputName, outputUnit } = v;
  const t = theme();
  const data = [];
  // Estimators scored against a simulated truth (torque, the observers' compressor flow)
  // show estimate vs truth; table filters show measured vs predicted output.
  const truthMode = isTorque || (est.kind !== "table-filter" && s.series.has("truth"));
  if (truthMode) {
    const tt = s.series.pick("truth");
    const te = s.series.pick("estimate");
    const er = s.series.pick("error");
    const what = isTorque ? "torque" : ((te ?? tt)?.name.replace(/_true$/, "") ?? "output");
    if (te) data.push(line(te, `estimated ${what}`, SERIES_COLORS[0], { width: 1.2 }));
    if (tt) data.push(line(tt, `true ${what}`, t.text, { width: 1.8 }));
    if (er) data.push({ ...line(er, "error", t.danger), yaxis: "y2" });
    const rj = rejectedMarkers(s.series, t.danger);
    if (rj) data.push(rj);
    if (!isTorque) setTitle(`${what}: estimated vs true`, "error (true − estimated) below");
    return {
      data,
      top: withUnit(what, (te ?? tt)?.unit ?? (isTorque ? "N·m" : "")),
      bottom: withUnit("error", er?.unit ?? te?.unit ?? ""),
    };
  }
  const me = s.series.pick("measured");
  const pr = s.series.pick("prediction");
  const re = s.series.pick("residual");
  if (me) data.push(line(me, "measured", t.text3, { width: 1.2 }));
  if (pr) data.push(line(pr, "predicted", SERIES_COLORS[0]));
  if (re) data.push({ ...line(re, "residual", SERIES_COLORS[1]), yaxis: "y2" });
  const rj = rejectedMarkers(s.series, t.danger);
  if (rj) data.push(rj);
  return {
    data,
    top: withUnit(outputName, (me ?? pr)?.unit ?? outputUnit),
    bottom: withUnit("residual", re?.unit ?? outputUnit),
  };
}

/**
 * Red × on the lower plot's zero line at the rejected samples' times, from the "rejected"
 * series (app/runs/results.py rejection_mask: 1 rejected, 0 accepted; min/max-decimated, so
 * every bucket holding a rejection keeps a 1). Thinned the same way to LINE_POINTS; null
 * when nothing was rejected.
 */
function rejectedMarkers(store, color) {
  const mask = store.data.rejected;
  if (!mask?.values?.length) return null;
  const { x, y } = decimate(mask.time, mask.values, LINE_POINTS);
  const times = x.filter((_, k) => y[k] !== null && y[k] >= 0.5);
  if (!times.length) return null;
  return {
    type: "scatter",
    mode: "markers",
    x: times,
    y: times.map(() => 0),
    yaxis: "y2",
    name: REJECTED_TRACE,
    marker: { symbol: "x-thin", size: 7, color, line: { color, width: 1.5 } },
    hovertemplate: `rejected sample<br>t = %{x:.3f} s<extra></extra>`,
  };
}

function line(series, name, color, { width = 1.5, dash = "solid" } = {}) {
  const { x, y } = decimate(series.time, series.values, LINE_POINTS);
  return {
    type: "scatter",
    mode: "lines",
    x,
    y,
    name,
    line: { color, width, dash },
    hovertemplate: `${name}: %{y:.4g} ${series.unit ?? ""}<br>t = %{x:.3f} s<extra></extra>`,
  };
}

/** The 0.5–99.5 % span of the values, padded, or null when it adds nothing to autorange. */
export function robustRange(values) {
  const finite = values.filter((x) => x !== null && Number.isFinite(x));
  if (finite.length < 50) return null;
  const lo = quantile(finite, 0.005);
  const hi = quantile(finite, 0.995);
  const min = Math.min(...finite);
  const max = Math.max(...finite);
  const span = hi - lo || Math.abs(hi) || 1;
  if (max - min < 1.6 * span) return null;
  return [lo - 0.15 * span, hi + 0.15 * span];
}
