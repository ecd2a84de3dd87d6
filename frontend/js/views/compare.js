/**
 * Runs & compare: every run in a table to pick from; for the chosen runs (usually the same
 * data through several estimators) the final maps side by side on one colour scale, their
 * differences to a reference run, the error signals overlaid, and a metrics table sortable
 * by any column. Refreshes itself while any of the runs is still going.
 * URL: /compare?runs=1,2&ref=1&sort=output_rmse:desc (reference run of the differences and the
 * sorted column, so a reload or a pasted link shows the same table).
 */
import { api, estimators } from "../api.js";
import { EVT, RUN_ACTIVE, SELECT } from "../constants.js";
import {
  card,
  fill,
  fmt,
  fmtDate,
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
import { diffNested, sameGrid } from "../grid-math.js";
import { MapPlot, SliceGroup } from "../map-plot.js";
import { axis, baseLayout, purge, react, SERIES_COLORS } from "../plot.js";
import { poll } from "../poll.js";
import { SCOPE } from "../scopes.js";
import { decimate, SeriesStore } from "../series.js";

export const title = "Runs & compare";

const REFRESH_MS = 2000;
/** Metrics where bigger is better; every other metric is an error (smaller is better). */
const HIGHER_BETTER = new Set(["coverage"]);
/** Counts, not scores: shown without a "best". */
const NEUTRAL = new Set(["samples", "accepted"]);
/** Columns of the metrics table that are not metrics (a metric's URL key is its own name). */
const PLAIN_COLUMNS = new Set(["id", "estimator", "status"]);
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
  const [catalog, allRuns, datasets] = await Promise.all([
    estimators(),
    api.all("/api/runs", { signal: ctx.signal }),
    api.all("/api/datasets", { signal: ctx.signal }),
  ]);
  const datasetName = (dsId) => datasets.find((d) => d.id === dsId)?.name ?? `#${dsId}`;

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
    pickerCard(allRuns, ids, datasetName, catalog, ctx),
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
  };
  const syncUrl = () =>
    ctx.setQuery({
      runs: ids.join(","),
      ref: view.ref !== ids[0] ? view.ref : undefined,
      sort: formatSort(view.sort),
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

  function metricsCard(runs) {
    const keys = [...new Set(runs.flatMap((r) => Object.keys(r.metrics ?? {})))];
    const columns = [
      { key: "id", label: "Run", value: (r) => r.id },
      { key: "estimator", label: "Estimator", value: (r) => r.estimator },
      { key: "status", label: "Status", value: (r) => r.status },
      ...keys.map((k) => ({
        key: `m:${k}`,
        label: metricLabel(k),
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
    const best = {};
    for (const c of columns.filter((x) => x.metric && !NEUTRAL.has(x.metric))) {
      const vals = runs.map(c.value).filter((v) => typeof v === "number");
      if (vals.length > 1)
        best[c.key] = HIGHER_BETTER.has(c.metric)
          ? Math.max(...vals)
          : Math.min(...vals.map(Math.abs));
    }
    const head = h(
      "tr",
      {},
      columns.map((c) => {
        const sort =
          view.sort.key === c.key ? (view.sort.dir > 0 ? "ascending" : "descending") : "none";
        return h(
          "th",
          { scope: "col", class: c.num ? "num" : null, "aria-sort": sort },
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
            return h("td", { class: `num${best[c.key] === v ? " best" : ""}` }, fmtDuration(v));
          const isBest =
            c.metric &&
            best[c.key] !== undefined &&
            typeof v === "number" &&
            (HIGHER_BETTER.has(c.metric) ? v === best[c.key] : Math.abs(v) === best[c.key]);
          return h(
            "td",
            { class: `num${isBest ? " best" : ""}`, title: isBest ? "best" : null },
            c.metric === "coverage" && typeof v === "number" ? `${fmt(v * 100, 3)} %` : fmt(v),
          );
        }),
      ),
    );
    return card({
      title: "Metrics",
      hint: "click a column to sort; best in green",
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

  function unitOf(run) {
    const ds = datasets.find((d) => d.id === run.dataset_id);
    return (
      ds?.channels?.find((c) => c.name === run.signals?.y)?.unit ?? run.config?.output_unit ?? ""
    );
  }

  function finalMapsCard(mapRuns) {
    // One colour scale for all maps; its ends are the 2–98 % quantiles so one wild cell
    // does not wash out the rest (hover still shows the true values).
    const all = mapRuns
      .flatMap((r) => r.final_version.values.flat(Infinity))
      .filter((v) => v !== null && Number.isFinite(v));
    const range = all.length ? [quantile(all, 0.02), quantile(all, 0.98)] : null;
    const tiles = mapRuns.map((r) => {
      const el = h("div", {
        class: "plot small",
        "data-plot": `final-${r.id}`,
        role: "img",
        "aria-label": `Final map of run ${r.id}`,
      });
      const label = r.signals?.y ?? "value";
      const p = new MapPlot(el, { kind: "value", unit: unitOf(r), label, slices: view.slices });
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
      h("h3", { style: { margin: "6px 0 10px" } }, "Final maps · shared colour scale"),
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
      const p = new MapPlot(el, {
        kind: "diff",
        unit: unitOf(r),
        label: r.signals?.y ?? "value",
        slices: view.slices,
      });
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

  function errorsCard(runs, seriesList) {
    const el = h("div", {
      class: "plot medium",
      "data-plot": "errors",
      role: "img",
      "aria-label": "Error signals of the runs overlaid",
    });
    const data = [];
    let unit = "";
    let trueTorque = null;
    runs.forEach((r, k) => {
      const raw = seriesList[k];
      if (!raw) return;
      const store = new SeriesStore();
      store.reset(raw.series ?? {}, raw.time ?? null);
      const err = store.pick("error") ?? store.pick("residual");
      if (!err) return;
      unit = err.unit || unit;
      const { x, y } = decimate(err.time, err.values);
      data.push({
        type: "scatter",
        mode: "lines",
        x,
        y,
        name: `#${r.id} ${r.estimator}`,
        line: { color: SERIES_COLORS[k % SERIES_COLORS.length], width: 1.3 },
        opacity: 0.9,
        hovertemplate: `#${r.id} ${r.estimator}: %{y:.4g} ${err.unit ?? ""}<extra></extra>`,
      });
      trueTorque = trueTorque ?? store.pick("truth");
    });
    if (!data.length) {
      return card({
        title: "Errors overlaid",
        body: h("p", { class: "help" }, "No error series yet."),
      });
    }
    pendingDraws.push(() =>
      react(
        el,
        data,
        baseLayout({
          xaxis: axis("time [s]"),
          yaxis: axis(withUnit(trueTorque ? "torque error" : "residual", unit), { zeroline: true }),
          margin: { l: 62, r: 12, t: 28, b: 40 },
        }),
      ),
    );
    view.plots.push(el);
    return card({
      title: "Errors overlaid",
      hint: trueTorque ? "true − estimated" : "measured − predicted",
      body: el,
      bodyCls: "tight",
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

/** All runs, filterable by dataset, with checkboxes to pick the ones to compare. */
function pickerCard(runs, selectedIds, datasetName, catalog, ctx) {
  const selected = new Set(selectedIds);
  const filter = h(
    "select",
    { id: "runs-dataset", "aria-label": "Filter by dataset" },
    h("option", { value: "" }, "All datasets"),
    [...new Set(runs.map((r) => r.dataset_id))].map((d) =>
      h("option", { value: String(d) }, datasetName(d)),
    ),
  );
  const button = h(
    "button",
    { type: "button", class: "primary", "data-compare-selected": "" },
    icon(ICONS.compare),
    "Compare selected",
  );
  const tbody = h("tbody");
  const count = () => {
    button.disabled = selected.size < 1;
    button.replaceChildren(
      icon(ICONS.compare),
      selected.size > 1 ? `Compare ${selected.size} runs` : "Compare selected",
    );
  };
  const renderRows = () => {
    const shown = runs.filter((r) => !filter.value || String(r.dataset_id) === filter.value);
    tbody.replaceChildren(
      ...shown.map((r) => {
        const est = catalog.find((e) => e.name === r.estimator);
        const box = h("input", {
          type: "checkbox",
          id: `pick-${r.id}`,
          checked: selected.has(r.id),
          "aria-label": `Select run ${r.id}`,
          onchange: (e) => {
            if (e.target.checked) selected.add(r.id);
            else selected.delete(r.id);
            count();
          },
        });
        const keyMetric = Object.entries(r.metrics ?? {}).find(([k]) =>
          ["ise", "output_rmse", "rmse", "mae"].includes(k),
        );
        return h(
          "tr",
          { dataset: { runId: r.id } },
          h("td", {}, box),
          h(
            "td",
            { class: "wrap" },
            h("a", { href: `/runs/${r.id}` }, `#${r.id}`),
            " ",
            h("span", { class: "sub" }, r.name ?? ""),
          ),
          h(
            "td",
            { class: "wrap" },
            h("code", { class: "tag accent" }, r.estimator),
            " ",
            h("span", { class: "sub" }, est?.title ?? ""),
          ),
          h("td", { class: "wrap" }, datasetName(r.dataset_id)),
          h("td", {}, statusBadge(r.status)),
          h(
            "td",
            { class: "num" },
            keyMetric ? `${metricLabel(keyMetric[0])} ${fmt(keyMetric[1])}` : "–",
          ),
          h("td", {}, fmtDate(r.created_at)),
        );
      }),
    );
  };
  filter.addEventListener("change", renderRows);
  button.addEventListener("click", () =>
    ctx.navigate(`/compare?runs=${[...selected].sort((a, b) => a - b).join(",")}`),
  );
  renderRows();
  count();
  return card({
    title: "All runs",
    actions: [h("div", { style: { width: "220px" } }, filter), button],
    bodyCls: "flush",
    body: runs.length
      ? h(
          "div",
          { class: "table-wrap" },
          h(
            "table",
            { class: "data", "data-runs-table": "" },
            h(
              "thead",
              {},
              h(
                "tr",
                {},
                h("th", { scope: "col" }, h("span", { class: "visually-hidden" }, "Select")),
                ...["Run", "Estimator", "Dataset", "Status", "Key metric", "Created"].map((t) =>
                  h("th", { scope: "col", class: t === "Key metric" ? "num" : null }, t),
                ),
              ),
            ),
            tbody,
          ),
        )
      : h("div", { class: "empty" }, "No runs yet. ", h("a", { href: "/runs/new" }, "Start one →")),
  });
}
