/**
 * The colour bar of a heatmap as plain HTML beside the plot (see MapPlot.drawBar): Plotly
 * would redraw its own on every frame, half the cost of a live frame; this one changes only
 * with the range. Linear ticks on nice steps, or one per decade on a log scale; an arrow at
 * an end says some cells lie beyond a pinned range.
 */
import { fmt, h } from "./dom.js";
import { niceStep } from "./grid-math.js";
import { decadeTicks } from "./plot.js";

/** Wraps the plot element in a div.mapplot and adds the bar after it. */
export class ColorBar {
  constructor(plotEl, kind) {
    const wrap = h("div", { class: "mapplot" });
    plotEl.parentElement.insertBefore(wrap, plotEl);
    wrap.append(plotEl);
    this.wrap = wrap;
    this.el = h("div", {
      class: "cbar",
      "aria-hidden": "true",
      dataset: { colorbarFor: plotEl.dataset.plot ?? kind },
    });
    wrap.append(this.el);
    this.key = "";
  }

  clear() {
    this.el.replaceChildren();
    this.key = "";
  }

  draw({ scale, range, log, title, top, height, clipped = { lo: false, hi: false } }) {
    if (!range) return;
    const key = JSON.stringify([range, log, title, top, height, scale[0][1], clipped]);
    if (key === this.key) return;
    this.key = key;
    const [lo, hi] = range;
    const ticks = log ? logTicks(lo, hi) : linearTicks(lo, hi);
    const stops = scale.map(([p, c]) => `${c} ${(p * 100).toFixed(1)}%`).join(", ");
    const frac = (v) => (hi > lo ? (v - lo) / (hi - lo) : 0.5);
    const grad = h(
      "div",
      {
        class: "cbar-grad",
        style: {
          background: `linear-gradient(to top, ${stops})`,
          top: `${top}px`,
          height: height ? `${height}px` : "80%",
        },
      },
      ticks
        .filter((t) => t.v >= lo - 1e-12 && t.v <= hi + 1e-12)
        .map((t) =>
          h(
            "span",
            { class: "cbar-tick", style: { bottom: `${(100 * frac(t.v)).toFixed(2)}%` } },
            t.label,
          ),
        ),
    );
    // Cells beyond a pinned range are drawn in the end colour; an arrow says so.
    const clip = (end) =>
      h(
        "span",
        {
          class: `cbar-clip ${end}`,
          title: `some cells are ${end === "hi" ? "above" : "below"} the scale`,
        },
        end === "hi" ? "▲" : "▼",
      );
    if (clipped.hi) grad.append(clip("hi"));
    if (clipped.lo) grad.append(clip("lo"));
    this.el.replaceChildren(h("div", { class: "cbar-title" }, title || "\u00a0"), grad);
  }
}

function linearTicks(lo, hi) {
  if (!(hi > lo)) return [{ v: lo, label: fmt(lo, 3) }];
  const step = niceStep(hi - lo);
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) {
    const r = Math.abs(v) < step * 1e-9 ? 0 : Number(v.toPrecision(12));
    out.push({ v: r, label: fmt(r, 3) });
  }
  return out;
}

function logTicks(lo, hi) {
  const { tickvals, ticktext } = decadeTicks(lo, hi);
  return tickvals.map((v, k) => ({ v, label: ticktext[k] }));
}
