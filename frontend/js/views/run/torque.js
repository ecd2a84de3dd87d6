/**
 * The torque estimators' own views: the adaptive laws' parameter estimates θ̂1, θ̂2 over time
 * (TQ (41)–(54): τ̂_e = [N, ṁ_ai] Θ̂), the running ISE while the run goes, and the scoring
 * window every torque index is computed over, shaded on each plot.
 *
 * Scoring window (estimation/metrics.py TORQUE_WINDOW_S, TQ §VI): 5–30 s after the record's
 * first sample, cut at its last. Running ISE (TQ (60)): ISE(t) = Σ_{t_k ∈ window, t_k ≤ t}
 * τ̃_k² Δt_k, τ̃ = τ − τ̂, Δt_k = t_{k+1} − t_k (the rectangle rule of torque_metrics): the
 * worker sends it at full rate as the series torque_nm_ise (estimation/metrics.py
 * running_ise); runningIse() recomputes it from the points the page holds when that series is
 * missing (runs stored before it), an approximation of the ISE card's exact value.
 */
import { card, fmt, h, withUnit } from "../../dom.js";
import { axis, baseLayout, purge, react, SERIES_COLORS, theme, withAlpha } from "../../plot.js";
import { decimate } from "../../series.js";
import { robustRange } from "./series.js";

/** TQ §VI: the indices are computed over 5–30 s of the record. */
export const TORQUE_WINDOW_S = Object.freeze([5, 30]);
/** The name of the window's shape in every torque plot's layout (tests look for it). */
export const WINDOW_NAME = "scoring window";
const LINE_POINTS = 1200;

/** The scoring window [from, to] in the series' time, or null before there is a series. */
export function scoringWindow(time) {
  if (!time?.length) return null;
  const t0 = time[0];
  const end = time.at(-1);
  const lo = t0 + TORQUE_WINDOW_S[0];
  if (!(end > lo)) return [lo, t0 + TORQUE_WINDOW_S[1]];
  return [lo, Math.min(t0 + TORQUE_WINDOW_S[1], end)];
}

/** The shaded band of the window over the whole height of a plot (layout.shapes). */
export function windowShape(window) {
  if (!window) return [];
  const t = theme();
  return [
    {
      type: "rect",
      name: WINDOW_NAME,
      xref: "x",
      yref: "paper",
      x0: window[0],
      x1: window[1],
      y0: 0,
      y1: 1,
      layer: "below",
      line: { width: 0 },
      fillcolor: withAlpha(t.dark ? "#fbbf24" : "#f59e0b", t.dark ? 0.1 : 0.09),
    },
  ];
}

/** The window's label at the top of the band (layout.annotations). */
function windowLabel(window) {
  if (!window) return [];
  return [
    {
      x: window[1],
      y: 1,
      xref: "x",
      yref: "paper",
      xanchor: "right",
      yanchor: "bottom",
      showarrow: false,
      text: `scoring window ${fmt(window[0], 3)}–${fmt(window[1], 3)} s`,
      font: { size: 10.5, color: theme().text3 },
    },
  ];
}

/** ISE(t) over the window along the points of the error series (module docstring). */
export function runningIse(time, error, window) {
  const x = [];
  const y = [];
  if (!window || !time?.length) return { x, y };
  let sum = 0;
  for (let k = 0; k < time.length; k += 1) {
    const t = time[k];
    if (t < window[0]) continue;
    if (t > window[1]) break;
    const next = k + 1 < time.length ? time[k + 1] : t + (k > 0 ? t - time[k - 1] : 0);
    const e = error[k];
    if (e !== null && Number.isFinite(e)) sum += e * e * (next - t);
    x.push(t);
    y.push(sum);
  }
  return { x, y };
}

/** θ̂1, θ̂2 (adaptive laws) and the running ISE: cards and their drawing. */
export function torqueViews(v) {
  const { s, run } = v;
  const thetaEl = h("div", {
    class: "plot short",
    "data-plot": "theta",
    role: "img",
    "aria-label": "Adaptive parameter estimates θ̂1 and θ̂2 over time",
  });
  const iseEl = h("div", {
    class: "plot short",
    "data-plot": "ise",
    role: "img",
    "aria-label": "Integral of the squared torque error over the scoring window so far",
  });
  const iseNote = h("span", { class: "hint", "data-ise-now": "" });
  const thetaCard = card({
    title: "Adaptive parameters",
    hint: "θ̂1 (left axis), θ̂2 (right axis); τ̂ = θ̂1·N + θ̂2·ṁ_ai",
    body: thetaEl,
    bodyCls: "tight",
  });
  thetaCard.hidden = true;
  const iseCard = card({
    title: "Running ISE",
    hint: "∫ τ̃² dt over the scoring window so far",
    actions: [iseNote],
    body: iseEl,
    bodyCls: "tight",
  });
  iseCard.hidden = true;
  const series = (name) => {
    const d = s.series.data[name];
    return d?.values?.length ? { name, ...d } : null;
  };
  // θ2 multiplies ṁ_ai in the config's air unit (estimation/torque/config.py air_unit).
  const airUnit = run.estimator_config?.air_unit ?? "kg/s";

  function drawTheta(window) {
    const th1 = series("theta1");
    const th2 = series("theta2");
    if (!th1 && !th2) return;
    thetaCard.hidden = false;
    const t = theme();
    const u1 = th1?.unit || "N·m/rpm";
    const u2 = th2?.unit || `N·m/(${airUnit})`;
    const data = [];
    if (th1) data.push(trace(th1, "θ̂1", u1, SERIES_COLORS[0]));
    if (th2) data.push({ ...trace(th2, "θ̂2", u2, SERIES_COLORS[1]), yaxis: "y2" });
    react(
      thetaEl,
      data,
      baseLayout({
        xaxis: axis("time [s]"),
        yaxis: axis(withUnit("θ̂1", u1), { color: SERIES_COLORS[0], ...ranged(th1) }),
        yaxis2: axis(withUnit("θ̂2", u2), {
          ...ranged(th2),
          overlaying: "y",
          side: "right",
          showgrid: false,
          tickmode: "auto", // Plotly's default here, "sync", puts θ̂1's ticks on θ̂2's scale
          nticks: 6,
          color: SERIES_COLORS[1],
        }),
        shapes: windowShape(window),
        annotations: windowLabel(window),
        margin: { l: 62, r: 62, t: 26, b: 40 },
        legend: { orientation: "h", x: 0, y: 1.12, font: { size: 11.5, color: t.text2 } },
      }),
    );
  }

  function drawIse(window, error) {
    if (!error) return;
    iseCard.hidden = false;
    const unit = `${error.unit ? `(${error.unit})²` : ""}·s`.replace(/^·/, "");
    const shown = unit === "(N·m)²·s" ? "N²·m²·s" : unit;
    // The worker's ISE at full rate (app/runs/results.py torque_nm_ise), else from the points
    // held here (an approximation: a long run's page holds a thinned series).
    const exact = series(`${error.name.replace(/_error$/, "")}_ise`);
    const { x, y } = exact
      ? { x: exact.time, y: exact.values }
      : runningIse(error.time, error.values, window);
    const final = s.metrics?.ise;
    iseNote.textContent = y.length ? `${fmt(y.at(-1))} ${shown} so far` : "window not reached";
    const data = [
      {
        type: "scatter",
        mode: "lines",
        name: "ISE so far",
        x,
        y,
        line: { color: SERIES_COLORS[3], width: 1.8 },
        hovertemplate: `ISE = %{y:.4g} ${shown}<br>t = %{x:.3f} s<extra></extra>`,
      },
    ];
    if (typeof final === "number" && window) {
      data.push({
        type: "scatter",
        mode: "lines",
        name: "ISE (all samples)",
        x: window,
        y: [final, final],
        line: { color: theme().text3, width: 1.2, dash: "dash" },
        hovertemplate: `ISE of the run = %{y:.4g} ${shown}<extra></extra>`,
      });
    }
    const time = error.time;
    react(
      iseEl,
      data,
      baseLayout({
        xaxis: axis("time [s]", time?.length ? { range: [time[0], time.at(-1)] } : {}),
        yaxis: axis(withUnit("ISE", shown), { rangemode: "tozero" }),
        shapes: windowShape(window),
        annotations: windowLabel(window),
        showlegend: data.length > 1,
        margin: { l: 62, r: 12, t: 26, b: 40 },
      }),
    );
  }

  return {
    thetaCard,
    iseCard,
    /** The window of the current series (null before the first points). */
    window: () => {
      const any = s.series.pick("error") ?? s.series.pick("estimate");
      return scoringWindow(any?.time);
    },
    draw(window) {
      drawTheta(window);
      drawIse(window, s.series.pick("error"));
    },
    destroy() {
      purge(thetaEl);
      purge(iseEl);
    },
  };
}

/** The start-up transient of an adaptive law would flatten the rest: frame the bulk. */
function ranged(series) {
  const range = series ? robustRange(series.values) : null;
  return range ? { range, autorange: false } : {};
}

function trace(series, name, unit, color) {
  const { x, y } = decimate(series.time, series.values, LINE_POINTS);
  return {
    type: "scatter",
    mode: "lines",
    x,
    y,
    name: withUnit(name, unit),
    line: { color, width: 1.5 },
    hovertemplate: `${name} = %{y:.4g} ${unit}<br>t = %{x:.3f} s<extra></extra>`,
  };
}
