/**
 * Sweeps: every sweep in a list (/sweeps); one sweep (/sweeps/{id}) as a table ranked by its
 * metric (sortable by any column), the metric against a chosen parameter (one point per run,
 * a log axis when the values span more than a decade) and, for a grid over two parameters, a
 * heatmap of the metric over the grid; the best run is highlighted, a click on a row or point
 * opens the run. While runs are queued or running the view refreshes every second, in place
 * (Plotly.react). URL: /sweeps/7?x=sigma_v&sort=metric:desc (plotted parameter, sorted column).
 */
import { api, estimators } from "../api.js";
import { EVT, GROUP_POLL_MS, LOG_AXIS_RATIO } from "../constants.js";
import { card, fill, fmt, h, icon, ICONS, metricLabel, pageHead, statusBadge } from "../dom.js";
import {
  focusSort,
  formatSort,
  groupTable,
  nextSort,
  parseSort,
  progressBar,
  followGroup,
  progressOf,
  sortHeader,
  sortRows,
} from "../groups.js";
import { axis, baseLayout, purge, react, SCALE_VIRIDIS, theme, withAlpha } from "../plot.js";
import { fmtMetric, metricFormula, metricUnit, PERCENT_METRICS } from "../metric-names.js";
import { poll } from "../poll.js";
import { runQuantity } from "../quantity.js";

export const title = "Sweeps";

/** Runs the "Compare top" link opens. */
const TOP = 3;
const DEFAULT_SORT = Object.freeze({ key: "rank", dir: 1 });
/** Up to this many distinct values of the plotted parameter get a tick each. */
const MAX_VALUE_TICKS = 12;
/** Trace names (what hover and tests look for). */
export const SWEEP_TRACE = Object.freeze({ runs: "runs", best: "best run" });

export function mount(root, ctx) {
  return ctx.params.id ? sweepView(root, ctx, Number(ctx.params.id)) : listView(root, ctx);
}

async function listView(root, ctx) {
  const host = h("div", { "data-sweeps": "" }, h("div", { class: "loading" }, "Loading sweeps…"));
  root.append(
    pageHead({
      title: "Sweeps",
      sub: "One dataset through one estimator at many settings, ranked by a metric.",
      actions: [
        h(
          "a",
          { class: "button primary", href: "/runs/new?mode=sweep" },
          icon(ICONS.plus),
          "New sweep",
        ),
      ],
    }),
    card({ title: "All sweeps", bodyCls: "flush", body: host }),
  );
  await poll(
    ctx.signal,
    async () => {
      const groups = await api.all("/api/sweeps", { signal: ctx.signal });
      fill(
        host,
        groupTable(groups, { kind: "sweep" }) ??
          h(
            "div",
            { class: "empty" },
            "No sweeps yet. ",
            h("a", { href: "/runs/new?mode=sweep" }, "Start one from New run →"),
          ),
      );
      return groups.some((g) => progressOf(g).active);
    },
    2 * GROUP_POLL_MS,
  );
  return undefined;
}

/** A parameter value for people: numbers formatted, anything else as it is. */
export function fmtParam(v) {
  return typeof v === "number" ? fmt(v) : v === null || v === undefined ? "–" : String(v);
}

/** Whether the values (numbers > 0) span more than LOG_AXIS_RATIO, so a log axis reads better. */
export function wantsLogAxis(values) {
  const xs = values.filter((v) => v !== null && v !== undefined);
  if (!xs.length || !xs.every((v) => typeof v === "number" && v > 0)) return false;
  return Math.max(...xs) / Math.min(...xs) > LOG_AXIS_RATIO;
}

/** The distinct values, numbers in ascending order, anything else as first seen. */
function distinct(values) {
  const out = [...new Set(values.filter((v) => v !== null && v !== undefined))];
  return out.every((v) => typeof v === "number") ? out.sort((a, b) => a - b) : out;
}

async function sweepView(root, ctx, id) {
  let sweep = await api.get(`/api/sweeps/${id}`, { signal: ctx.signal });
  const request = sweep.request ?? {};
  const params = Object.keys(request.parameters ?? {});
  const dataset = await api
    .get(`/api/datasets/${request.dataset_id}`, { signal: ctx.signal })
    .catch(() => null);
  const metricName = metricLabel(sweep.metric ?? "metric");
  // The metric's unit: its runs' output unit (their dataset's column, else the map quantity),
  // or per cent for shares; plotted shares keep their 0–1 values and format their ticks.
  const catalog = await estimators().catch(() => []);
  const torque = catalog.find((e) => e.name === request.estimator)?.kind === "torque";
  const outputUnit = runQuantity(
    { ...request, config: request.config ?? {} },
    dataset ? [dataset] : [],
  ).unit;
  const metricUnitText = metricUnit(sweep.metric ?? "", outputUnit, { torque });
  const percent = PERCENT_METRICS.has(sweep.metric);
  const metricTitle = metricUnitText ? `${metricName} [${metricUnitText}]` : metricName;
  const hoverFormat = percent ? ":.3%" : ":.4g";
  const hoverUnit = metricUnitText && !percent ? ` ${metricUnitText}` : "";
  const lowerBetter = sweep.order !== "max";
  const isGrid = request.samples === null || request.samples === undefined;
  const wantX = ctx.query.get("x");
  const view = {
    sort: parseSort(ctx.query.get("sort"), DEFAULT_SORT),
    x: params.includes(wantX) ? wantX : params[0],
    bound: new WeakSet(),
    plots: [],
  };

  /* ---------- head ---------- */
  const compareLink = h(
    "a",
    { class: "button", href: "/compare", "data-compare-top": "", hidden: true },
    icon(ICONS.compare),
    `Compare top ${TOP}`,
  );
  const how = isGrid
    ? `a grid of ${sweep.runs.length} settings`
    : `${request.samples} random draws (seed ${request.seed ?? 0})`;
  root.append(
    pageHead({
      crumbs: h("a", { href: "/sweeps" }, "Sweeps"),
      title: sweep.name,
      sub:
        `${sweep.estimator} on ${dataset ? `“${dataset.name}”` : `dataset #${request.dataset_id}`} · ${how} · ` +
        `ranked by ${metricName}, ${lowerBetter ? "lowest" : "highest"} first`,
      actions: [compareLink],
    }),
  );
  const progressHost = h("div", {
    class: "stack",
    style: { gap: "8px", marginBottom: "16px" },
    "data-sweep-progress": "",
  });
  root.append(progressHost);

  /* ---------- ranked table ---------- */
  const columns = [
    { key: "rank", label: "Rank", num: true, value: (r) => view.rank.get(r.id) ?? null },
    { key: "run", label: "Run", value: (r) => r.id },
    ...params.map((p) => ({
      key: p,
      label: p,
      num: true,
      param: p,
      value: (r) => r.params?.[p] ?? null,
    })),
    {
      key: "metric",
      label: metricName,
      title: metricFormula(sweep.metric ?? "") || null,
      num: true,
      value: (r) => r.metric ?? null,
    },
    { key: "status", label: "Status", value: (r) => r.status },
  ];
  if (!columns.some((c) => c.key === view.sort.key)) view.sort = { ...DEFAULT_SORT };
  const thead = h("thead");
  const tbody = h("tbody");
  const table = h("table", { class: "data", "data-sweep-table": "" }, thead, tbody);

  /* ---------- plots ---------- */
  const scatterEl = h("div", {
    class: "plot medium",
    "data-plot": "sweep-scatter",
    role: "img",
    "aria-label": `${metricName} against the chosen parameter, one point per run`,
  });
  view.plots.push(scatterEl);
  const picker = h(
    "select",
    { id: "sweep-x", name: "x" },
    params.map((p) => h("option", { value: p, selected: p === view.x }, p)),
  );
  picker.addEventListener("change", () => {
    view.x = picker.value;
    syncUrl();
    drawPlots();
  });
  const showHeatmap = isGrid && params.length === 2;
  const heatmapEl = showHeatmap
    ? h("div", {
        class: "plot medium",
        "data-plot": "sweep-heatmap",
        role: "img",
        "aria-label": `${metricName} over the grid of ${params.join(" and ")}`,
      })
    : null;
  if (heatmapEl) view.plots.push(heatmapEl);

  const scatterCard = card({
    title: "Parameter vs metric",
    hint: "best run starred; click a point to open its run",
    actions: [
      h("label", { for: "sweep-x", class: "inline" }, "Parameter"),
      h("div", { style: { width: "200px" } }, picker),
    ],
    body: scatterEl,
    bodyCls: "tight",
  });
  root.append(
    h(
      "div",
      { class: "stack" },
      card({
        title: "Ranking",
        hint: `best first by ${metricName}; click a column to sort, a row to open its run`,
        bodyCls: "flush",
        body: h("div", { class: "table-wrap" }, table),
      }),
      heatmapEl
        ? h(
            "div",
            { class: "grid cols-2" },
            scatterCard,
            card({
              title: "Metric over the grid",
              hint: "best run outlined; click a cell to open its run",
              body: heatmapEl,
              bodyCls: "tight",
            }),
          )
        : scatterCard,
    ),
  );

  function syncUrl() {
    const defaultSort = view.sort.key === DEFAULT_SORT.key && view.sort.dir === DEFAULT_SORT.dir;
    ctx.setQuery({
      x: view.x !== params[0] ? view.x : undefined,
      sort: defaultSort ? undefined : formatSort(view.sort),
    });
  }

  function render() {
    // Rank: the API's order (best first by the metric); runs without the metric yet have none.
    view.rank = new Map(
      sweep.runs
        .filter((r) => r.metric !== null && r.metric !== undefined)
        .map((r, k) => [r.id, k + 1]),
    );
    const best = sweep.best_run_id;
    const bestRun = sweep.runs.find((r) => r.id === best);
    fill(
      progressHost,
      progressBar(sweep, "Runs of the sweep finished"),
      bestRun
        ? h(
            "div",
            { class: "help", "data-sweep-best": "" },
            "Best so far: ",
            h("a", { href: `/runs/${best}` }, `run #${best}`),
            ` · ${metricName} ${fmtMetric(sweep.metric, bestRun.metric)}${hoverUnit} · `,
            params.map((p) => `${p} = ${fmtParam(bestRun.params?.[p])}`).join(", "),
          )
        : null,
    );
    const top = sweep.runs
      .filter((r) => view.rank.has(r.id))
      .slice(0, TOP)
      .map((r) => r.id);
    compareLink.hidden = top.length === 0;
    compareLink.href = `/compare?runs=${top.join(",")}`;
    compareLink.replaceChildren(
      icon(ICONS.compare),
      top.length < TOP ? `Compare top ${top.length}` : `Compare top ${TOP}`,
    );
    renderTable();
    drawPlots();
  }

  function renderTable() {
    fill(
      thead,
      sortHeader(columns, view.sort, (key) => {
        view.sort = nextSort(view.sort, key);
        syncUrl();
        renderTable();
        focusSort(thead, key);
      }),
    );
    const best = sweep.best_run_id;
    fill(
      tbody,
      sortRows(sweep.runs, columns, view.sort).map((r) => {
        const isBest = r.id === best;
        return h(
          "tr",
          {
            class: `clickable${isBest ? " best-row" : ""}`,
            dataset: { runId: r.id },
            onclick: (e) => {
              if (!e.target.closest("a, button")) ctx.navigate(`/runs/${r.id}`);
            },
          },
          columns.map((c) => {
            if (c.key === "rank") {
              return h(
                "td",
                { class: "num" },
                view.rank.get(r.id) ?? "–",
                isBest
                  ? h("span", { class: "tag ok", style: { marginLeft: "6px" } }, "best")
                  : null,
              );
            }
            if (c.key === "run")
              return h(
                "td",
                {},
                h("a", { href: `/runs/${r.id}`, "aria-label": `Open run ${r.id}` }, `#${r.id}`),
              );
            if (c.param) return h("td", { class: "num" }, fmtParam(r.params?.[c.param]));
            if (c.key === "metric")
              return h(
                "td",
                { class: `num${isBest ? " best" : ""}`, "data-metric": r.metric ?? "" },
                fmtMetric(sweep.metric, r.metric),
              );
            return h("td", { title: r.error ?? null }, statusBadge(r.status));
          }),
        );
      }),
    );
  }

  /* ---------- drawing ---------- */
  function onClick(el) {
    if (view.bound.has(el) || typeof el.on !== "function") return;
    view.bound.add(el);
    el.on("plotly_click", (ev) => {
      const runId = Number(ev?.points?.[0]?.customdata?.[0]);
      if (Number.isInteger(runId) && runId > 0) ctx.navigate(`/runs/${runId}`);
    });
  }

  function drawPlots() {
    Promise.resolve(drawScatter()).then(() => onClick(scatterEl));
    if (heatmapEl) Promise.resolve(drawHeatmap()).then(() => onClick(heatmapEl));
  }

  function drawScatter() {
    const t = theme();
    const x = view.x;
    const others = params.filter((p) => p !== x);
    const pts = sweep.runs.filter(
      (r) => r.metric !== null && r.metric !== undefined && r.params && x in r.params,
    );
    const all = sweep.runs.map((r) => r.params?.[x]);
    // The axis type follows every value of the sweep, not only the finished runs: it stays put while runs finish.
    const log = wantsLogAxis(all);
    const numeric = all.every((v) => typeof v === "number");
    const best = sweep.best_run_id;
    const bestRun = pts.find((r) => r.id === best);
    const detail = others.length ? "<br>%{customdata[1]}" : "";
    const data = [
      {
        type: "scatter",
        mode: "markers",
        name: SWEEP_TRACE.runs,
        x: pts.map((r) => r.params[x]),
        y: pts.map((r) => r.metric),
        customdata: pts.map((r) => [
          r.id,
          others.map((p) => `${p} = ${fmtParam(r.params[p])}`).join("<br>"),
        ]),
        hovertemplate: `run #%{customdata[0]}<br>${x} = %{x}${detail}<br><b>${metricName} = %{y${hoverFormat}}${hoverUnit}</b><extra></extra>`,
        marker: {
          size: pts.map((r) => (r.id === best ? 17 : 9)),
          symbol: pts.map((r) => (r.id === best ? "star" : "circle")),
          color: pts.map((r) => (r.id === best ? t.ok : withAlpha(t.accent, 0.8))),
          line: { color: t.surface, width: 1 },
        },
      },
    ];
    const annotations = bestRun
      ? [
          {
            x: log ? Math.log10(bestRun.params[x]) : bestRun.params[x],
            y: bestRun.metric,
            text: `best #${best}`,
            showarrow: false,
            yshift: 18,
            font: { size: 11.5, color: t.ok },
          },
        ]
      : [];
    // A handful of values: a tick at each; many (random draws): the axis' own ticks (decades on a log axis).
    const values = distinct(all);
    const ticks =
      numeric && values.length <= MAX_VALUE_TICKS
        ? { tickmode: "array", tickvals: values, ticktext: values.map(fmtParam) }
        : log
          ? { dtick: 1 }
          : {};
    return react(
      scatterEl,
      data,
      baseLayout({
        xaxis: axis(x, { type: log ? "log" : numeric ? "linear" : "category", ...ticks }),
        yaxis: axis(metricTitle, percent ? { tickformat: ".1%" } : {}),
        margin: { l: 64, r: 16, t: 16, b: 48 },
        showlegend: false,
        annotations,
        uirevision: x,
      }),
    );
  }

  function drawHeatmap() {
    const t = theme();
    const px = view.x;
    const py = params.find((p) => p !== px);
    const gx = distinct(request.parameters[px] ?? []);
    const gy = distinct(request.parameters[py] ?? []);
    const cell = (vx, vy) =>
      sweep.runs.find((r) => r.params?.[px] === vx && r.params?.[py] === vy) ?? null;
    const runs = gy.map((vy) => gx.map((vx) => cell(vx, vy)));
    const z = runs.map((row) => row.map((r) => r?.metric ?? null));
    const customdata = runs.map((row, j) =>
      row.map((r, i) => [r?.id ?? null, fmtParam(gx[i]), fmtParam(gy[j]), r?.status ?? "not run"]),
    );
    const data = [
      {
        type: "heatmap",
        name: metricName,
        x: gx.map((_, i) => i),
        y: gy.map((_, j) => j),
        z,
        customdata,
        hovertemplate:
          `${px} = %{customdata[1]}<br>${py} = %{customdata[2]}<br><b>${metricName} = %{z${hoverFormat}}${hoverUnit}</b>` +
          "<br>run #%{customdata[0]} (%{customdata[3]})<extra></extra>",
        // Best at the bright end of the scale whichever way the metric ranks.
        colorscale: SCALE_VIRIDIS,
        reversescale: lowerBetter,
        xgap: 1,
        ygap: 1,
        hoverongaps: false,
        colorbar: {
          thickness: 12,
          outlinewidth: 0,
          len: 0.95,
          x: 1.01,
          xpad: 6,
          tickfont: { size: 11, color: t.text3 },
          title: { text: metricTitle, side: "right", font: { size: 11.5, color: t.text2 } },
          ...(percent ? { tickformat: ".1%" } : {}),
        },
      },
    ];
    const bi = runs.findIndex((row) => row.some((r) => r?.id === sweep.best_run_id));
    if (bi >= 0) {
      const i = runs[bi].findIndex((r) => r?.id === sweep.best_run_id);
      data.push({
        type: "scatter",
        mode: "lines",
        name: SWEEP_TRACE.best,
        hoverinfo: "skip",
        showlegend: false,
        x: [i - 0.5, i + 0.5, i + 0.5, i - 0.5, i - 0.5],
        y: [bi - 0.5, bi - 0.5, bi + 0.5, bi + 0.5, bi - 0.5],
        line: { color: t.trailEdge, width: 3 },
      });
    }
    const ticks = (values) => ({
      tickmode: "array",
      tickvals: values.map((_, k) => k),
      ticktext: values.map(fmtParam),
      range: [-0.5, values.length - 0.5],
      autorange: false,
      showgrid: false,
      zeroline: false,
    });
    return react(
      heatmapEl,
      data,
      baseLayout({
        xaxis: axis(px, ticks(gx)),
        yaxis: axis(py, ticks(gy)),
        margin: { l: 64, r: 8, t: 12, b: 48 },
        showlegend: false,
        uirevision: px,
      }),
    );
  }

  /* ---------- refresh while runs go ---------- */
  await followGroup(ctx, `/api/sweeps/${id}`, progressHost, (fresh) => {
    if (fresh) sweep = fresh;
    render();
    return sweep;
  });

  const onTheme = () => drawPlots();
  window.addEventListener(EVT.themeChange, onTheme);
  return () => {
    window.removeEventListener(EVT.themeChange, onTheme);
    view.plots.forEach(purge);
  };
}
