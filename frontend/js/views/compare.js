/**
 * Runs & compare: every run in a table to pick from; for the chosen runs (usually the same
 * data through several estimators) the final maps side by side on one colour scale, their
 * differences to a reference run, the error signals overlaid, and a metrics table sortable
 * by any column. Refreshes itself while any of the runs is still going.
 * URL: /compare?runs=1,2&ref=1&sort=output_rmse:desc&y=full (reference run of the differences,
 * the sorted column and the errors' full y-range, so a reload or a pasted link shows the same).
 */
import { api, estimators } from "../api.js";
import { EVT, RUN_ACTIVE, SELECT } from "../constants.js";
import {
  card,
  fill,
  fmt,
  fmtDuration,
  h,
  icon,
  ICONS,
  metricLabel,
  pageHead,
  quantile,
  statusBadge,
  withUnit,
} from "../dom.js";
import { errorOf, groupByAxis, stackAxes } from "../error-axes.js";
import { diffNested, sameGrid } from "../grid-math.js";
import { MapPlot, SliceGroup } from "../map-plot.js";
import { axis, baseLayout, purge, react, SERIES_COLORS } from "../plot.js";
import { fmtMetric, metricFormula } from "../metric-names.js";
import { poll } from "../poll.js";
import { runQuantity } from "../quantity.js";
import { SCOPE } from "../scopes.js";
import { runsListCard } from "./runs-list.js";
import { decimate, SeriesStore } from "../series.js";

export const title = "Runs & compare";

const REFRESH_MS = 2000;
/** Metrics where bigger is better; every other metric is an error (smaller is better). */
const HIGHER_BETTER = new Set(["coverage"]);
/** Counts, not scores: shown without a "best". */
const NEUTRAL = new Set(["samples", "accepted"]);
/** Columns of the metrics table that are not metrics (a metric's URL key is its own name). */
const PLAIN_COLUMNS = new Set(["id", "estimator", "status"]);
/** Metrics that compare across quantities (a share, a run time, a normalised innovation). */
const CROSS_QUANTITY = (metric) =>
  metric === "coverage" || metric === "run_s" || metric.startsWith("nis:");
const SORT_DIRS = { asc: 1, desc: -1 };

/** "output_rmse:desc" → {key: "m:output_rmse", dir: -1}; "id:asc" → {key: "id", dir: 1}. */
export function parseSort(text) {
  const m = /^(.+):(asc|desc)$/.exec(text ?? "");
  if (!m) return { key: null, dir: 1 };
  return { key: PLAIN_COLUMNS.has(m[1]) ? m[1] : `m:${m[1]}`, dir: SORT_DIRS[m[2]] };
}

export function formatSort({ key, dir }) {
  if (!key) return undefined;
  return `${key.replace(/^m:/, "")}:${dir > 0 ? "asc" : "desc"}`;
}

export async function mount(root, ctx) {
  const ids = (ctx.query.get("runs") ?? "")
    .split(",")
    .map(Number)
    .filter((n) => Number.isInteger(n) && n > 0);
  const cleanups = [];
  const [catalog, datasets] = await Promise.all([
    estimators(),
    api.all("/api/datasets", { signal: ctx.signal }),
  ]);
  /** What a run's map and errors are in: the unit of its output or map, else their name.
   * Runs of different quantities get their own colour scale and their own "best". */
  const quantityKey = (run) => {
    const { label, unit } = runQuantity(run, datasets);
    return unit || `\u0000${label}`;
  };

  root.append(
    pageHead({
      title: ids.length ? `Compare ${ids.length} run${ids.length > 1 ? "s" : ""}` : "Runs",
      sub: ids.length
        ? "Final maps on one colour scale, their differences, errors overlaid, and metrics side by side."
        : "Every run so far. Tick the runs to compare (usually the same data through several estimators).",
      actions: [
        h(
          "a",
          { class: "button primary", href: "/runs/new", "data-needs": SCOPE.run },
          icon(ICONS.plus),
          "New run",
        ),
      ],
    }),
  );

  const comparison = h("div", { class: "stack", "data-comparison": "" });
  root.append(
    comparison,
    h("div", { style: { height: "16px" } }),
    runsListCard({ selectedIds: ids, datasets, catalog, ctx }).element,
  );

  if (!ids.length) return () => cleanups.forEach((f) => f());

  comparison.append(h("div", { class: "loading" }, "Loading runs…"));
  const refQuery = Number(ctx.query.get("ref"));
  const view = {
    sort: parseSort(ctx.query.get("sort")),
    ref: ids.includes(refQuery) ? refQuery : ids[0],
    plots: [],
    last: null,
    slices: new SliceGroup(),
    fullRange: ctx.query.get("y") === "full",
  };
  const syncUrl = () =>
    ctx.setQuery({
      runs: ids.join(","),
      ref: view.ref !== ids[0] ? view.ref : undefined,
      sort: formatSort(view.sort),
      y: view.fullRange ? "full" : undefined,
    });

  /** Fetch and draw the comparison; whether to fetch again (a run is still going). */
  async function load() {
    let body;
    try {
      body = await api.get("/api/compare", { query: { runs: ids.join(",") }, signal: ctx.signal });
    } catch (err) {
      if (err.name === "AbortError") return;
      comparison.replaceChildren(
        h("div", { class: "banner error", role: "alert", "data-field": "runs" }, err.message),
      );
      return;
    }
    const runs = body.runs ?? [];
    const series = await Promise.all(
      runs.map((r) =>
        api
          .get(`/api/runs/${r.id}/series`, { query: { points: 1500 }, signal: ctx.signal })
          .catch(() => null),
      ),
    );
    view.last = { runs, series };
    render();
    // The run list below was fetched once, at mount: keep its status badges current.
    for (const r of runs) {
      for (const badge of root.querySelectorAll(`tr[data-run-id="${r.id}"] .badge[data-status]`))
        badge.replaceWith(statusBadge(r.status));
    }
    return runs.some((r) => RUN_ACTIVE.has(r.status));
  }

  function render() {
    const { runs, series } = view.last;
    view.plots.forEach((p) => (p instanceof MapPlot ? p.destroy() : purge(p)));
    view.plots = [];
    const mapRuns = runs.filter((r) => r.final_version?.values);
    fill(
      comparison,
      metricsCard(runs),
      mapRuns.length ? finalMapsCard(mapRuns) : null,
      mapRuns.length > 1 ? diffCard(mapRuns) : null,
      errorsCard(runs, series),
    );
    // Plotly needs the nodes in the document to size them.
    for (const draw of pendingDraws.splice(0)) draw();
  }

  const pendingDraws = [];

  /** Every metric any of the runs has (metricFormula reads rmse by whether map_rmse is there). */
  function metricsOf(runs) {
    return Object.assign({}, ...runs.map((r) => r.metrics ?? {}));
  }

  function metricsCard(runs) {
    const keys = [...new Set(runs.flatMap((r) => Object.keys(r.metrics ?? {})))];
    const columns = [
      { key: "id", label: "Run", value: (r) => r.id },
      { key: "estimator", label: "Estimator", value: (r) => r.estimator },
      { key: "status", label: "Status", value: (r) => r.status },
      ...keys.map((k) => ({
        key: `m:${k}`,
        label: metricLabel(k),
        title: metricFormula(k, metricsOf(runs)),
        num: true,
        value: (r) => r.metrics?.[k] ?? null,
        metric: k,
      })),
    ];
    const sorted = [...runs];
    const col = columns.find((c) => c.key === view.sort.key);
    if (col) {
      sorted.sort((a, b) => {
        const va = col.value(a);
        const vb = col.value(b);
        if (va === null) return 1;
        if (vb === null) return -1;
        return (va > vb ? 1 : va < vb ? -1 : 0) * view.sort.dir;
      });
    }
    // "Best" compares like with like: an error in ppm is never better than one in kg/s.
    const groupOf = (c, r) => (CROSS_QUANTITY(c.metric) ? "" : quantityKey(r));
    const best = {};
    for (const c of columns.filter((x) => x.metric && !NEUTRAL.has(x.metric))) {
      best[c.key] = new Map();
      for (const group of new Set(runs.map((r) => groupOf(c, r)))) {
        const vals = runs
          .filter((r) => groupOf(c, r) === group)
          .map(c.value)
          .filter((v) => typeof v === "number");
        if (vals.length > 1)
          best[c.key].set(
            group,
            HIGHER_BETTER.has(c.metric) ? Math.max(...vals) : Math.min(...vals.map(Math.abs)),
          );
      }
    }
    const bestOf = (c, r) => best[c.key]?.get(groupOf(c, r));
    const head = h(
      "tr",
      {},
      columns.map((c) => {
        const sort =
          view.sort.key === c.key ? (view.sort.dir > 0 ? "ascending" : "descending") : "none";
        return h(
          "th",
          { scope: "col", class: c.num ? "num" : null, title: c.title || null, "aria-sort": sort },
          h(
            "button",
            {
              type: "button",
              class: "sort",
              "data-sort": c.key,
              onclick: () => {
                view.sort = { key: c.key, dir: view.sort.key === c.key ? -view.sort.dir : 1 };
                syncUrl();
                render();
                root.querySelector(SELECT.sortButton(c.key))?.focus();
              },
            },
            c.label,
          ),
        );
      }),
    );
    const rows = sorted.map((r) =>
      h(
        "tr",
        { dataset: { runId: r.id } },
        columns.map((c) => {
          const v = c.value(r);
          if (c.key === "id")
            return h(
              "td",
              { class: "wrap" },
              h("a", { href: `/runs/${r.id}` }, `#${r.id}`),
              " ",
              h("span", { class: "sub" }, r.name ?? ""),
            );
          if (c.key === "estimator")
            return h("td", {}, h("code", { class: "tag accent" }, r.estimator));
          if (c.key === "status") {
            return h(
              "td",
              {},
              statusBadge(r.status),
              RUN_ACTIVE.has(r.status)
                ? h("span", { class: "sub" }, ` ${fmt((r.progress ?? 0) * 100, 3)} %`)
                : null,
            );
          }
          if (c.metric === "run_s")
            return h("td", { class: `num${bestOf(c, r) === v ? " best" : ""}` }, fmtDuration(v));
          const top = c.metric ? bestOf(c, r) : undefined;
          const isBest =
            top !== undefined &&
            typeof v === "number" &&
            (HIGHER_BETTER.has(c.metric) ? v === top : Math.abs(v) === top);
          return h(
            "td",
            { class: `num${isBest ? " best" : ""}`, title: isBest ? "best" : null },
            c.metric ? fmtMetric(c.metric, v) : fmt(v),
          );
        }),
      ),
    );
    const mixed = new Set(runs.map(quantityKey)).size > 1;
    return card({
      title: "Metrics",
      hint: mixed
        ? "click a column to sort; best in green among runs of the same quantity"
        : "click a column to sort; best in green",
      bodyCls: "flush",
      body: h(
        "div",
        { class: "table-wrap" },
        h(
          "table",
          { class: "data", "data-metrics-table": "" },
          h("thead", {}, head),
          h("tbody", {}, rows),
        ),
      ),
    });
  }

  function finalMapsCard(mapRuns) {
    // One colour scale for the maps of one quantity (never ppm and kg/s on one scale); its
    // ends are the 2–98 % quantiles so one wild cell does not wash out the rest (hover
    // still shows the true values).
    const ranges = new Map();
    for (const key of new Set(mapRuns.map(quantityKey))) {
      const all = mapRuns
        .filter((r) => quantityKey(r) === key)
        .flatMap((r) => r.final_version.values.flat(Infinity))
        .filter((v) => v !== null && Number.isFinite(v));
      ranges.set(key, all.length ? [quantile(all, 0.02), quantile(all, 0.98)] : null);
    }
    const tiles = mapRuns.map((r) => {
      const range = ranges.get(quantityKey(r));
      const el = h("div", {
        class: "plot small",
        "data-plot": `final-${r.id}`,
        role: "img",
        "aria-label": `Final map of run ${r.id}`,
      });
      const { label, unit } = runQuantity(r, datasets);
      const p = new MapPlot(el, { kind: "value", unit, label, slices: view.slices });
      p.barLabel = label;
      if (range && range[1] > range[0]) p.setRange(range);
      view.plots.push(p);
      pendingDraws.push(() => p.render(r.final_version));
      return card({
        title: `#${r.id} ${r.estimator}`,
        hint: r.final_version.label ?? `version at t = ${fmt(r.final_version.time_s, 4)} s`,
        body: el,
        bodyCls: "tight",
        actions: [statusBadge(r.status)],
      });
    });
    return h(
      "section",
      { "aria-label": "Final maps" },
      h(
        "h3",
        { style: { margin: "6px 0 10px" } },
        ranges.size > 1
          ? "Final maps · one colour scale per quantity"
          : "Final maps · shared colour scale",
      ),
      h("div", { class: "map-tiles" }, tiles),
    );
  }

  function diffCard(mapRuns) {
    if (!mapRuns.some((r) => r.id === view.ref)) view.ref = mapRuns[0].id;
    const ref = mapRuns.find((r) => r.id === view.ref);
    const refSelect = h(
      "select",
      { id: "diff-ref", "aria-label": "Reference run" },
      mapRuns.map((r) =>
        h(
          "option",
          { value: String(r.id), selected: r.id === view.ref },
          `#${r.id} ${r.estimator}`,
        ),
      ),
    );
    refSelect.addEventListener("change", () => {
      view.ref = Number(refSelect.value);
      syncUrl();
      render();
      root.querySelector(SELECT.id(refSelect.id))?.focus();
    });
    const others = mapRuns.filter((r) => r.id !== ref.id);
    const diffs = others.map((r) => ({
      r,
      ok: sameGrid(ref.final_version.axes, r.final_version.axes),
    }));
    const span = Math.max(
      1e-12,
      quantile(
        diffs
          .filter((d) => d.ok)
          .flatMap(({ r }) =>
            diffNested(ref.final_version.values, r.final_version.values).flat(Infinity),
          )
          .filter((v) => v !== null && Number.isFinite(v))
          .map(Math.abs),
        0.98,
      ) ?? 0,
    );
    const tiles = diffs.map(({ r, ok }) => {
      if (!ok) {
        return card({
          title: `#${r.id} − #${ref.id}`,
          body: h(
            "p",
            { class: "help" },
            "Different grids: the maps cannot be subtracted cell by cell.",
          ),
        });
      }
      const el = h("div", {
        class: "plot small",
        "data-plot": `diff-${r.id}`,
        role: "img",
        "aria-label": `Run ${r.id} minus run ${ref.id}`,
      });
      const { label, unit } = runQuantity(r, datasets);
      const p = new MapPlot(el, { kind: "diff", unit, label, slices: view.slices });
      p.barLabel = `Δ ${label}`;
      view.plots.push(p);
      const frame = {
        ...r.final_version,
        values: diffNested(ref.final_version.values, r.final_version.values),
        trail: null,
      };
      p.setRange([-span, span]);
      pendingDraws.push(() => p.render(frame));
      return card({
        title: `#${r.id} ${r.estimator} − #${ref.id} ${ref.estimator}`,
        body: el,
        bodyCls: "tight",
      });
    });
    return h(
      "section",
      { "aria-label": "Difference maps" },
      h(
        "div",
        { class: "row", style: { margin: "6px 0 10px" } },
        h("h3", {}, "Differences to"),
        h("div", { style: { width: "240px" } }, refSelect),
      ),
      h("div", { class: "map-tiles" }, tiles),
    );
  }

  /**
   * The runs' error signals overlaid: one subplot (and y-axis) per quantity and unit, titled by
   * the signal ("Torque error", "MAF error", "Residual") with the series' own unit, on a shared
   * time axis. Each y-axis spans the 1st–99th percentile of its data plus a margin, so a t = 0
   * transient does not flatten the rest; "Full range" shows every value.
   */
  function errorsCard(runs, seriesList) {
    const el = h("div", {
      class: "plot medium",
      "data-plot": "errors",
      role: "img",
      "aria-label": "Error signals of the runs overlaid",
    });
    const entries = [];
    runs.forEach((r, k) => {
      const raw = seriesList[k];
      if (!raw) return;
      const store = new SeriesStore();
      store.reset(raw.series ?? {}, raw.time ?? null);
      const err = errorOf(store);
      if (!err) return;
      const { x, y } = decimate(err.time, err.values);
      entries.push({
        ...err,
        run: r,
        color: SERIES_COLORS[k % SERIES_COLORS.length],
        x,
        values: y,
      });
    });
    if (!entries.length) {
      return card({
        title: "Errors overlaid",
        body: h("p", { class: "help" }, "No error series yet."),
      });
    }
    const groups = groupByAxis(entries);
    const axes = stackAxes(groups);
    const data = groups.flatMap((g, i) =>
      g.entries.map((e) => ({
        type: "scatter",
        mode: "lines",
        x: e.x,
        y: e.values,
        yaxis: axes[i].yaxis,
        name: `#${e.run.id} ${e.run.estimator}`,
        legendgroup: `run-${e.run.id}`,
        line: { color: e.color, width: 1.3 },
        opacity: 0.9,
        hovertemplate: `#${e.run.id} ${e.run.estimator}: %{y:.4g} ${e.unit ?? ""}<extra>${g.title}</extra>`,
      })),
    );
    el.style.height = `${300 + 230 * (groups.length - 1)}px`;
    const full = view.fullRange;
    const layout = baseLayout({
      xaxis: axis("time [s]", { anchor: axes[axes.length - 1].yaxis }),
      margin: { l: 62, r: 12, t: 28, b: 40 },
      uirevision: full ? "full" : "robust", // a toggle resets any zoom
      annotations: groups.map((g, i) => ({
        text: `<b>${g.title}</b>`,
        xref: "paper",
        yref: "paper",
        x: 1, // the legend takes the left of the top edge
        y: axes[i].domain[1],
        xanchor: "right",
        yanchor: "bottom",
        showarrow: false,
        font: { size: 12 },
      })),
    });
    groups.forEach((g, i) => {
      const a = axes[i];
      layout[a.layoutKey] = axis(withUnit(g.title, g.unit), {
        zeroline: true,
        domain: a.domain,
        anchor: "x",
        ...(full || !a.range ? { autorange: true } : { range: a.range, autorange: false }),
      });
    });
    pendingDraws.push(() => react(el, data, layout));
    view.plots.push(el);
    const clipped = axes.reduce((n, a) => n + a.outside, 0);
    const toggle = h(
      "button",
      {
        type: "button",
        "data-full-range": "",
        "aria-pressed": String(full),
        title: full
          ? "Scale each axis to the 1st–99th percentile of its data"
          : "Scale each axis to all its data, transients and spikes included",
        onclick: () => {
          view.fullRange = !view.fullRange;
          syncUrl();
          render();
          root.querySelector("[data-full-range]")?.focus();
        },
      },
      "Full range",
    );
    const hints = [...new Set(groups.map((g) => g.entries[0].hint))].join("; ");
    return card({
      title: "Errors overlaid",
      hint: full
        ? `${hints}; full range`
        : `${hints}; y: 1st–99th percentile${clipped ? `, ${clipped} points beyond` : ""}`,
      body: el,
      bodyCls: "tight",
      actions: [toggle],
    });
  }

  const onTheme = () => view.last && render();
  window.addEventListener(EVT.themeChange, onTheme);
  cleanups.push(() => window.removeEventListener(EVT.themeChange, onTheme));
  await poll(ctx.signal, load, REFRESH_MS);
  return () => {
    view.plots.forEach((p) => (p instanceof MapPlot ? p.destroy() : purge(p)));
    cleanups.forEach((f) => f());
  };
}
