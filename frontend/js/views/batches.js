/**
 * Fleet batches: every batch in a list (/batches); one batch (/batches/{id}): a run per
 * vehicle's log and, once every run has succeeded, the aggregate map (the cell-wise
 * inverse-variance merge of the vehicles' maps) beside one vehicle's standardised deviation z
 * from the other vehicles' merge, on a diverging colour scale fixed to ±5 with the cells where
 * |z| > 3 outlined, and the number of such cells per vehicle. 3-D tables are shown by slice,
 * both maps on the same slice. Refreshes every second while runs are queued or running.
 * URL: /batches/4?vehicle=2 (the vehicle shown, counted from 1).
 */
import { api } from "../api.js";
import { DEVIATION_RANGE, DEVIATION_Z, EVT, GROUP_POLL_MS, RUN_ACTIVE } from "../constants.js";
import {
  card,
  fill,
  fmtDuration,
  h,
  icon,
  ICONS,
  metricLabel,
  pageHead,
  statusBadge,
} from "../dom.js";
import { followGroup, groupTable, progressBar, progressOf } from "../groups.js";
import { MapPlot, SliceGroup } from "../map-plot.js";
import { fmtMetric, metricFormula } from "../metric-names.js";
import { axis, baseLayout, purge, react, STATIC_CONFIG, theme, withAlpha } from "../plot.js";
import { poll } from "../poll.js";

export const title = "Batches";

/** Counts, not scores: not shown in the runs table. */
const HIDDEN_METRICS = new Set(["samples", "accepted"]);

export function mount(root, ctx) {
  return ctx.params.id ? batchView(root, ctx, Number(ctx.params.id)) : listView(root, ctx);
}

async function listView(root, ctx) {
  const datasets = await api.all("/api/datasets", { signal: ctx.signal }).catch(() => []);
  const datasetName = (id) => datasets.find((d) => d.id === id)?.name ?? `#${id}`;
  const host = h("div", { "data-batches": "" }, h("div", { class: "loading" }, "Loading batches…"));
  root.append(
    pageHead({
      title: "Batches",
      sub: "One configuration over a fleet's logs, merged into one map, with each vehicle's deviation from the rest.",
      actions: [
        h("a", { class: "button", href: "/datasets" }, "Pick datasets…"),
        h(
          "a",
          { class: "button primary", href: "/runs/new?mode=batch" },
          icon(ICONS.plus),
          "New batch",
        ),
      ],
    }),
    card({ title: "All batches", bodyCls: "flush", body: host }),
  );
  await poll(
    ctx.signal,
    async () => {
      const groups = await api.all("/api/batches", { signal: ctx.signal });
      fill(
        host,
        groupTable(groups, { kind: "batch", datasetName }) ??
          h(
            "div",
            { class: "empty" },
            "No batches yet. Tick several datasets in ",
            h("a", { href: "/datasets" }, "Datasets"),
            " and choose “Run batch…”.",
          ),
      );
      return groups.some((g) => progressOf(g).active);
    },
    2 * GROUP_POLL_MS,
  );
  return undefined;
}

/**
 * Index tuples of the cells of a nested table where |value| > limit (nulls skipped).
 * @returns {number[][]}
 */
export function cellsBeyond(nested, limit, prefix = []) {
  if (!Array.isArray(nested)) return [];
  const out = [];
  nested.forEach((v, i) => {
    if (Array.isArray(v)) out.push(...cellsBeyond(v, limit, [...prefix, i]));
    else if (v !== null && Number.isFinite(v) && Math.abs(v) > limit) out.push([...prefix, i]);
  });
  return out;
}

async function batchView(root, ctx, id) {
  const [first, datasets] = await Promise.all([
    api.get(`/api/batches/${id}`, { signal: ctx.signal }),
    api.all("/api/datasets", { signal: ctx.signal }).catch(() => []),
  ]);
  let batch = first;
  const request = batch.request ?? {};
  const datasetName = (dsId) => datasets.find((d) => d.id === dsId)?.name ?? `dataset #${dsId}`;
  const output = request.signals?.y ?? request.config?.output ?? "value";
  const unit =
    datasets
      .find((d) => d.id === request.dataset_ids?.[0])
      ?.channels?.find((c) => c.name === output)?.unit ?? "";
  const view = {
    vehicle: Number(ctx.query.get("vehicle")) || null,
    slices: new SliceGroup(),
    agg: null,
    dev: null,
    drawn: false,
    barsBound: false,
  };

  const compareLink = h(
    "a",
    { class: "button", href: "/compare", "data-compare-batch": "" },
    icon(ICONS.compare),
    "Compare the runs",
  );
  root.append(
    pageHead({
      crumbs: h("a", { href: "/batches" }, "Batches"),
      title: batch.name,
      sub: `${batch.estimator} over ${batch.runs.length} logs · the aggregate is the inverse-variance merge per cell`,
      actions: [compareLink],
    }),
  );
  const progressHost = h("div", { style: { marginBottom: "16px" }, "data-batch-progress": "" });
  const aggregateHost = h("div", { class: "stack", "data-aggregate": "" });
  const runsHost = h("div", { class: "table-wrap" });
  root.append(
    progressHost,
    h(
      "div",
      { class: "stack" },
      aggregateHost,
      card({ title: "Runs", hint: "one per vehicle's log", bodyCls: "flush", body: runsHost }),
    ),
  );

  /** Vehicles in the batch's order (1-based numbers); their index in the aggregate by run id. */
  const zIndex = (run) => batch.aggregate?.run_ids?.indexOf(run.id) ?? -1;
  const vehicleCount = () => batch.runs.length;

  function chooseVehicle(n, { focus = false } = {}) {
    view.vehicle = Math.min(Math.max(1, n), vehicleCount());
    ctx.setQuery({ vehicle: view.vehicle });
    if (view.picker) view.picker.value = String(view.vehicle);
    drawDeviation();
    drawBars();
    renderRuns();
    if (focus) view.picker?.focus();
  }

  /* ---------- runs table ---------- */
  function renderRuns() {
    const keys = [...new Set(batch.runs.flatMap((r) => Object.keys(r.metrics ?? {})))].filter(
      (k) => !HIDDEN_METRICS.has(k),
    );
    const all = Object.assign({}, ...batch.runs.map((r) => r.metrics ?? {}));
    const deviating = batch.aggregate?.deviating_cells ?? null;
    const head = h(
      "tr",
      {},
      h("th", { scope: "col" }, "Vehicle"),
      h("th", { scope: "col" }, "Dataset"),
      h("th", { scope: "col" }, "Run"),
      h("th", { scope: "col" }, "Status"),
      keys.map((k) =>
        h(
          "th",
          { scope: "col", class: "num", title: metricFormula(k, all) || null },
          metricLabel(k),
        ),
      ),
      deviating ? h("th", { scope: "col", class: "num" }, `Cells |z| > ${DEVIATION_Z}`) : null,
    );
    const rows = batch.runs.map((r, k) => {
      const n = k + 1;
      const zi = zIndex(r);
      return h(
        "tr",
        {
          dataset: { runId: r.id, vehicle: n },
          "aria-current": deviating && view.vehicle === n ? "true" : null,
        },
        h(
          "td",
          {},
          deviating
            ? h(
                "button",
                {
                  type: "button",
                  class: "linklike",
                  "data-show-vehicle": n,
                  "aria-label": `Show the deviation of vehicle ${n}`,
                  onclick: () => {
                    chooseVehicle(n);
                    runsHost.querySelector(`[data-show-vehicle="${n}"]`)?.focus();
                  },
                },
                `Vehicle ${n}`,
              )
            : `Vehicle ${n}`,
        ),
        h(
          "td",
          { class: "wrap" },
          h("a", { href: `/datasets?id=${r.dataset_id}` }, datasetName(r.dataset_id)),
        ),
        h(
          "td",
          {},
          h("a", { href: `/runs/${r.id}`, "aria-label": `Open run ${r.id}` }, `#${r.id}`),
        ),
        h("td", { title: r.error ?? null }, statusBadge(r.status)),
        keys.map((key) => {
          const v = r.metrics?.[key] ?? null;
          return h("td", { class: "num" }, key === "run_s" ? fmtDuration(v) : fmtMetric(key, v));
        }),
        deviating
          ? h(
              "td",
              { class: "num", "data-deviating": zi >= 0 ? deviating[zi] : "" },
              zi >= 0 ? String(deviating[zi]) : "–",
            )
          : null,
      );
    });
    fill(
      runsHost,
      h(
        "table",
        { class: "data", "data-batch-table": "" },
        h("thead", {}, head),
        h("tbody", {}, rows),
      ),
    );
  }

  /* ---------- aggregate, deviation and the count per vehicle ---------- */
  function renderAggregate() {
    const agg = batch.aggregate;
    if (!agg) {
      const failed = batch.runs.filter(
        (r) => !RUN_ACTIVE.has(r.status) && r.status !== "succeeded",
      ).length;
      const { done, total } = progressOf(batch);
      fill(
        aggregateHost,
        failed
          ? h(
              "div",
              { class: "banner warn", role: "status" },
              `No aggregate map: it needs every run to succeed, and ${failed} of ${total} did not.`,
            )
          : h(
              "div",
              { class: "banner info", role: "status" },
              `The aggregate map appears once every run has succeeded (${done} of ${total} finished).`,
            ),
      );
      return;
    }
    if (view.drawn) return;
    view.drawn = true;
    if (!view.vehicle) {
      // Start with the vehicle that deviates most: the one worth a look.
      const counts = agg.deviating_cells ?? [];
      const worst = counts.reduce((best, c, k) => (c > counts[best] ? k : best), 0);
      view.vehicle = batch.runs.findIndex((r) => r.id === agg.run_ids[worst]) + 1 || 1;
    }
    view.vehicle = Math.min(Math.max(1, view.vehicle), vehicleCount());
    const aggEl = h("div", {
      class: "plot map",
      "data-plot": "aggregate",
      role: "img",
      "aria-label": "Aggregate map of the fleet",
    });
    view.agg = new MapPlot(aggEl, { kind: "value", unit, label: output, slices: view.slices });
    const cards = [
      card({
        title: "Aggregate map",
        hint: `merge of ${agg.run_ids.length} vehicles`,
        body: aggEl,
        bodyCls: "tight",
      }),
    ];
    if (agg.z) {
      const devEl = h("div", {
        class: "plot map",
        "data-plot": "deviation",
        role: "img",
        "aria-label": `Standardised deviation of the chosen vehicle from the others, cells beyond ${DEVIATION_Z} outlined`,
      });
      view.dev = new MapPlot(devEl, { kind: "deviation", label: "z", slices: view.slices });
      view.dev.setRange(DEVIATION_RANGE);
      view.picker = h(
        "select",
        { id: "batch-vehicle", name: "vehicle" },
        batch.runs.map((r, k) =>
          h(
            "option",
            { value: String(k + 1), selected: k + 1 === view.vehicle },
            `Vehicle ${k + 1} · ${datasetName(r.dataset_id)}`,
          ),
        ),
      );
      view.picker.addEventListener("change", () => chooseVehicle(Number(view.picker.value)));
      view.count = h("p", { class: "help", "data-deviating-count": "", "aria-live": "polite" });
      cards.push(
        card({
          title: "Deviation from the others",
          hint: `z, scale fixed to ±${DEVIATION_RANGE[1]}; |z| > ${DEVIATION_Z} outlined`,
          actions: [
            h("label", { for: "batch-vehicle", class: "inline" }, "Vehicle"),
            h("div", { style: { width: "240px" } }, view.picker),
          ],
          body: h("div", {}, devEl, view.count),
          bodyCls: "tight",
        }),
      );
      view.barsEl = h("div", {
        class: "plot short",
        "data-plot": "deviating-bars",
        role: "img",
        "aria-label": `Cells with |z| > ${DEVIATION_Z} per vehicle`,
      });
    } else {
      cards.push(
        card({
          title: "Deviation from the others",
          body: h(
            "p",
            { class: "help" },
            "The runs kept no variances, so their deviations cannot be standardised.",
          ),
        }),
      );
    }
    fill(
      aggregateHost,
      h("div", { class: "grid cols-2" }, cards),
      view.barsEl
        ? card({
            title: `Cells with |z| > ${DEVIATION_Z} per vehicle`,
            hint: "click a bar to show that vehicle",
            body: view.barsEl,
            bodyCls: "tight",
          })
        : null,
    );
    drawAll();
  }

  function drawAll() {
    const agg = batch.aggregate;
    if (!agg) return;
    view.agg?.render({ axes: agg.axes, values: agg.values, variances: agg.variances });
    drawDeviation();
    drawBars();
  }

  function drawDeviation() {
    const agg = batch.aggregate;
    if (!agg?.z || !view.dev) return;
    const run = batch.runs[view.vehicle - 1];
    const k = run ? zIndex(run) : -1;
    if (k < 0) return;
    const z = agg.z[k];
    const outlines = cellsBeyond(z, DEVIATION_Z);
    view.dev.render({ axes: agg.axes, values: z, weights: agg.weights?.[k] ?? null, outlines });
    const n = agg.deviating_cells?.[k] ?? outlines.length;
    view.count.textContent =
      `Vehicle ${view.vehicle} (${datasetName(run.dataset_id)}): ${n} cell${n === 1 ? "" : "s"} with |z| > ${DEVIATION_Z}` +
      (agg.axes.length > 2 ? " across all slices" : "") +
      ".";
  }

  function drawBars() {
    const agg = batch.aggregate;
    if (!view.barsEl || !agg?.deviating_cells) return;
    const t = theme();
    const order = batch.runs.map((r) => zIndex(r));
    const labels = batch.runs.map((_, k) => `Vehicle ${k + 1}`);
    const drawn = react(
      view.barsEl,
      [
        {
          type: "bar",
          x: labels,
          y: order.map((k) => (k >= 0 ? agg.deviating_cells[k] : null)),
          customdata: batch.runs.map((r, k) => [k + 1, datasetName(r.dataset_id)]),
          marker: {
            color: labels.map((_, k) =>
              k + 1 === view.vehicle ? t.accent : withAlpha(t.accent, 0.35),
            ),
            line: { color: t.accent, width: 1 },
          },
          hovertemplate: "%{x} (%{customdata[1]}): %{y} cells<extra></extra>",
        },
      ],
      baseLayout({
        xaxis: axis("", { type: "category" }),
        yaxis: axis(`cells |z| > ${DEVIATION_Z}`, { rangemode: "tozero" }),
        margin: { l: 56, r: 12, t: 10, b: 36 },
        showlegend: false,
      }),
      { ...STATIC_CONFIG },
    );
    Promise.resolve(drawn).then(() => {
      if (view.barsBound || typeof view.barsEl.on !== "function") return;
      view.barsBound = true;
      view.barsEl.on("plotly_click", (ev) => {
        const n = Number(ev?.points?.[0]?.customdata?.[0]);
        if (Number.isInteger(n)) chooseVehicle(n);
      });
    });
  }

  function render() {
    fill(progressHost, progressBar(batch, "Runs of the batch finished"));
    compareLink.href = `/compare?runs=${batch.runs.map((r) => r.id).join(",")}`;
    renderAggregate();
    renderRuns();
  }

  // Once every run is done the aggregate is in the same answer: nothing more to wait for.
  await followGroup(ctx, `/api/batches/${id}`, progressHost, (fresh) => {
    if (fresh) batch = fresh;
    render();
    return batch;
  });

  const onTheme = () => {
    if (view.drawn) drawAll();
  };
  window.addEventListener(EVT.themeChange, onTheme);
  return () => {
    window.removeEventListener(EVT.themeChange, onTheme);
    view.agg?.destroy();
    view.dev?.destroy();
    if (view.barsEl) purge(view.barsEl);
  };
}
