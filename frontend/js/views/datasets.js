/**
 * Datasets: upload a log (datasets-upload.js: drag and drop, progress, units per column,
 * channels and raster), simulate a scenario, list and delete datasets, preview every channel
 * with its unit, ingest's notes and masked samples, and map columns to the signals an
 * estimator needs before starting a run. Ticking several datasets offers a fleet batch over
 * them (the New-run form in batch mode, those datasets chosen).
 */
import { api, clearErrors, estimators, scenarios, showError } from "../api.js";
import { EVT } from "../constants.js";
import { needs, SCOPE } from "../scopes.js";
import {
  card,
  clear,
  confirmDialog,
  fmt,
  fmtDate,
  fmtDuration,
  fmtInt,
  h,
  icon,
  ICONS,
  pageHead,
  toast,
  uploadProgress,
  withUnit,
} from "../dom.js";
import {
  encodeSignals,
  guessColumn,
  guessTable,
  KIND_TITLES,
  needsTable,
  rolesOf,
} from "../mapping.js";
import { axis, baseLayout, purge, react, STATIC_CONFIG, theme } from "../plot.js";
import { ingestReport, maskedTag, uploadCard } from "./datasets-upload.js";

export const title = "Datasets";

const PREVIEW_POINTS = 400;
/** The controls of the column mapping (signal and axis pickers). */
const CONTROL = "select";

export async function mount(root, ctx) {
  const state = {
    datasets: [],
    selected: Number(ctx.query.get("id")) || null,
    plots: [],
    picked: new Set(),
  };
  const batchButton = h(
    "button",
    {
      type: "button",
      class: "small",
      "data-run-batch": "",
      disabled: true,
      onclick: () => {
        const ids = [...state.picked].sort((a, b) => a - b);
        ctx.navigate(`/runs/new?dataset=${ids[0]}&mode=batch&datasets=${ids.join(",")}`);
      },
    },
    icon(ICONS.grid),
    "Run batch…",
  );
  const syncBatch = () => {
    for (const id of state.picked)
      if (!state.datasets.some((d) => d.id === id)) state.picked.delete(id);
    batchButton.disabled = state.picked.size < 2;
    batchButton.replaceChildren(
      icon(ICONS.grid),
      state.picked.size >= 2 ? `Run batch on ${state.picked.size} datasets…` : "Run batch…",
    );
    batchButton.title = state.picked.size < 2 ? "Tick two or more datasets for a fleet batch" : "";
  };
  const list = h(
    "div",
    { "data-dataset-list": "" },
    h("div", { class: "loading" }, "Loading datasets…"),
  );
  const preview = h("div", { class: "stack", "data-dataset-preview": "" });

  root.append(
    pageHead({
      title: "Datasets",
      sub: "Bring a drive log or simulate a cycle with known truth, then map its columns to an estimator.",
    }),
    h(
      "div",
      { class: "grid side-l" },
      h("div", { class: "stack" }, uploadCard(ctx, onCreated), simulateCard(ctx, onCreated)),
      h(
        "div",
        { class: "stack" },
        card({
          title: "Your datasets",
          hint: "tick several for a fleet batch",
          actions: [batchButton],
          bodyCls: "flush",
          body: list,
        }),
        preview,
      ),
    ),
  );

  async function refresh() {
    try {
      state.datasets = await api.all("/api/datasets", { signal: ctx.signal });
    } catch (err) {
      if (err.name === "AbortError") return;
      list.replaceChildren(h("div", { class: "banner error", role: "alert" }, err.message));
      return;
    }
    renderList();
  }

  function renderList() {
    syncBatch();
    if (!state.datasets.length) {
      list.replaceChildren(
        h("div", { class: "empty" }, "No datasets yet — upload a log or simulate a scenario."),
      );
      return;
    }
    const rows = state.datasets.map((d) =>
      h(
        "tr",
        { "aria-current": d.id === state.selected ? "true" : null, dataset: { datasetId: d.id } },
        h(
          "td",
          {},
          h("input", {
            type: "checkbox",
            id: `pick-ds-${d.id}`,
            "data-pick-dataset": d.id,
            checked: state.picked.has(d.id),
            "aria-label": `Pick ${d.name} for a batch`,
            onchange: (e) => {
              if (e.target.checked) state.picked.add(d.id);
              else state.picked.delete(d.id);
              syncBatch();
            },
          }),
        ),
        h(
          "td",
          { class: "wrap" },
          h(
            "button",
            {
              class: "linklike",
              type: "button",
              "data-select-dataset": d.id,
              "aria-label": `Preview dataset ${d.name}`,
              onclick: () => select(d.id),
            },
            d.name,
          ),
          " ",
          h("span", { class: "tag" }, d.source),
          " ",
          maskedTag(d),
        ),
        h("td", { class: "num" }, fmtInt(d.rows)),
        h("td", { class: "num" }, `${fmt(d.rate_hz, 3)} Hz`),
        h("td", { class: "num" }, fmtDuration(d.duration_s)),
        h("td", { class: "num" }, String(d.channels?.length ?? 0)),
        h("td", { class: "date" }, fmtDate(d.created_at)),
        h(
          "td",
          { class: "num" },
          h(
            "div",
            { class: "row end" },
            h(
              "a",
              {
                class: "button small",
                href: `/runs/new?dataset=${d.id}`,
                "aria-label": `New run on ${d.name}`,
                "data-needs": SCOPE.run,
              },
              icon(ICONS.play),
              "New run",
            ),
            h(
              "button",
              {
                class: "small danger icon",
                type: "button",
                "aria-label": `Delete dataset ${d.name}`,
                title: "Delete",
                "data-needs": SCOPE.admin,
                onclick: () => remove(d),
              },
              icon(ICONS.trash),
            ),
          ),
        ),
      ),
    );
    list.replaceChildren(
      h(
        "div",
        { class: "table-wrap" },
        h(
          "table",
          { class: "data compact" },
          h(
            "thead",
            {},
            h(
              "tr",
              {},
              h(
                "th",
                { scope: "col" },
                h("span", { class: "visually-hidden" }, "Pick for a batch"),
              ),
              h("th", { scope: "col" }, "Name"),
              h("th", { scope: "col", class: "num" }, "Rows"),
              h("th", { scope: "col", class: "num" }, "Rate"),
              h("th", { scope: "col", class: "num" }, "Duration"),
              h("th", { scope: "col", class: "num" }, "Channels"),
              h("th", { scope: "col" }, "Created"),
              h(
                "th",
                { scope: "col", class: "num" },
                h("span", { class: "visually-hidden" }, "Actions"),
              ),
            ),
          ),
          h("tbody", {}, rows),
        ),
      ),
    );
  }

  async function select(id) {
    state.selected = id;
    ctx.setQuery({ id });
    renderList();
    const dataset =
      state.datasets.find((d) => d.id === id) ??
      (await api.get(`/api/datasets/${id}`, { signal: ctx.signal }));
    await renderPreview(dataset);
  }

  async function renderPreview(dataset) {
    state.plots.forEach(purge);
    state.plots = [];
    const channelsHost = h(
      "div",
      { class: "channel-grid" },
      h("div", { class: "loading" }, "Loading channels…"),
    );
    preview.replaceChildren(
      card({
        title: `Channels of “${dataset.name}”`,
        hint:
          `${fmtInt(dataset.rows)} rows · ${fmt(dataset.rate_hz, 3)} Hz · ${fmtDuration(dataset.duration_s)}` +
          (dataset.has_truth ? " · with truth" : ""),
        body: [ingestReport(dataset), channelsHost],
      }),
      await mappingCard(ctx, dataset),
    );
    let pv;
    try {
      pv = await api.get(`/api/datasets/${dataset.id}/preview`, {
        query: { points: PREVIEW_POINTS },
        signal: ctx.signal,
      });
    } catch (err) {
      if (err.name !== "AbortError")
        channelsHost.replaceChildren(h("div", { class: "banner error" }, err.message));
      return;
    }
    clear(channelsHost);
    for (const [name, ch] of Object.entries(pv.channels ?? {})) {
      const values = ch.values ?? [];
      const finite = values.filter((v) => v !== null);
      const plot = h("div", {
        class: "spark",
        role: "img",
        "aria-label": `Plot of ${withUnit(name, ch.unit)} over time`,
      });
      channelsHost.append(
        h(
          "div",
          { class: "channel", "data-channel": name },
          h(
            "div",
            { class: "ch-head" },
            h("span", { class: "ch-name", title: name }, name),
            h("span", { class: "ch-unit" }, ch.unit ? `[${ch.unit}]` : "no unit"),
          ),
          dataset.masked?.[name]
            ? h(
                "div",
                { class: "ch-masked", "data-masked": dataset.masked[name] },
                `${fmtInt(dataset.masked[name])} samples masked (filled from valid neighbours)`,
              )
            : null,
          h(
            "div",
            { class: "ch-range" },
            finite.length
              ? `${fmt(Math.min(...finite))} … ${fmt(Math.max(...finite))}`
              : "no finite values",
          ),
          plot,
        ),
      );
      const draw = () => sparkline(plot, pv.time, values, ch.unit);
      draw();
      plot.redraw = draw;
      state.plots.push(plot);
    }
  }

  /** Why the dataset cannot simply go, in words (the API's message names its parameters). */
  async function inUseMessage(dataset) {
    let runs = "some runs";
    try {
      const page = await api.get("/api/runs", {
        query: { dataset_id: dataset.id, limit: 1 },
        signal: ctx.signal,
      });
      runs = page.total === 1 ? "1 run" : `${fmtInt(page.total)} runs`;
    } catch {
      // The count is a nicety: the question stands without it.
    }
    return (
      `“${dataset.name}” is used by ${runs}. Deleting it also deletes those runs ` +
      "and their map versions. This cannot be undone."
    );
  }

  async function remove(dataset) {
    const ok = await confirmDialog(
      `Delete “${dataset.name}” (${fmtInt(dataset.rows)} rows)? This cannot be undone.`,
      { title: "Delete dataset", confirmLabel: "Delete", danger: true },
    );
    if (!ok) return;
    try {
      await api.del(`/api/datasets/${dataset.id}`);
    } catch (err) {
      if (err.code !== "conflict") return showError(root, err);
      const force = await confirmDialog(await inUseMessage(dataset), {
        title: "Dataset in use",
        confirmLabel: "Delete everything",
        danger: true,
      });
      if (!force) return;
      try {
        await api.del(`/api/datasets/${dataset.id}`, { query: { force: "true" } });
      } catch (err2) {
        return showError(root, err2);
      }
    }
    toast(`Deleted “${dataset.name}”.`);
    if (state.selected === dataset.id) {
      state.selected = null;
      ctx.setQuery({});
      preview.replaceChildren();
    }
    refresh();
  }

  async function onCreated(dataset) {
    toast(
      `Dataset “${dataset.name}” ready: ${fmtInt(dataset.rows)} rows, ${dataset.channels?.length ?? 0} channels.`,
    );
    await refresh();
    await select(dataset.id);
  }

  await refresh();
  if (state.selected) {
    select(state.selected).catch((err) => err.name !== "AbortError" && showError(root, err));
  }
  const onTheme = () => state.plots.forEach((p) => p.redraw?.());
  window.addEventListener(EVT.themeChange, onTheme);
  return () => {
    window.removeEventListener(EVT.themeChange, onTheme);
    state.plots.forEach(purge);
  };
}

/* ---------- simulate ---------- */

function simulateCard(ctx, onCreated) {
  const select = h(
    "select",
    { id: "sim-scenario", name: "scenario" },
    h("option", { value: "" }, "Loading scenarios…"),
  );
  const seed = h("input", {
    type: "number",
    id: "sim-seed",
    name: "seed",
    value: "0",
    step: "1",
    min: "0",
  });
  const name = h("input", {
    type: "text",
    id: "sim-name",
    name: "name",
    placeholder: "defaults to the scenario name",
  });
  const duration = h("input", {
    type: "number",
    id: "sim-duration",
    name: "duration_s",
    min: "0",
    step: "any",
    placeholder: "whole record",
    "aria-describedby": "sim-duration-help",
  });
  const durationHelp = h("div", { class: "help", id: "sim-duration-help" });
  const about = h("div", { class: "help", "data-scenario-about": "" });
  const submit = h("button", { type: "submit", class: "primary" }, icon(ICONS.flask), "Simulate");
  const progress = h("div", { class: "help", role: "status", "data-sim-progress": "" });
  const bar = uploadProgress({ label: "Simulation progress" });
  bar.el.dataset.simBar = "";
  let list = [];
  const form = h(
    "form",
    { novalidate: true, "aria-label": "Simulate a scenario" },
    h("div", { class: "field" }, h("label", { for: "sim-scenario" }, "Scenario"), select, about),
    h(
      "div",
      { class: "fields two" },
      h("div", { class: "field" }, h("label", { for: "sim-seed" }, "Seed"), seed),
      h("div", { class: "field" }, h("label", { for: "sim-name" }, "Name"), name),
    ),
    h(
      "div",
      { class: "field" },
      h("label", { for: "sim-duration" }, "Duration [s]"),
      duration,
      durationHelp,
    ),
    h("div", { class: "banner error", "data-form-error": "", hidden: true }),
    bar.el,
    h("div", { class: "row end" }, progress, submit),
  );

  const describe = () => {
    const s = list.find((x) => x.name === select.value);
    about.replaceChildren(
      s
        ? `${s.description} (${fmt(s.rate_hz, 3)} Hz, ${fmtDuration(s.duration_s)}; for ${s.estimators.join(", ")})`
        : "",
    );
    // The scenario's record bounds the duration; empty simulates all of it.
    duration.max = s ? String(s.duration_s) : "";
    duration.placeholder = s ? `whole record, ${fmt(s.duration_s, 4)} s` : "whole record";
    durationHelp.textContent = s
      ? `Simulate only the first seconds (up to ${fmt(s.duration_s, 4)} s); empty: all of it.`
      : "";
  };
  select.addEventListener("change", describe);
  scenarios()
    .then((items) => {
      list = items;
      select.replaceChildren(
        ...items.map((s) =>
          h(
            "option",
            { value: s.name },
            s.title && s.title !== s.name ? `${s.name} — ${s.title}` : s.name,
          ),
        ),
      );
      describe();
    })
    .catch((err) => showError(form, err));

  form.addEventListener("submit", async (e) => {
    e.preventDefault();
    clearErrors(form);
    submit.disabled = true;
    submit.replaceChildren(icon(ICONS.flask), "Simulating…");
    // The server streams the plant integrator's progress (share of its steps), then the
    // dataset (POST /api/datasets/simulate/stream, docs/rest-api.md#simulate-progress).
    const started = performance.now();
    bar.start();
    let ok = false;
    try {
      const body = { scenario: select.value, seed: Number(seed.value || 0) };
      if (name.value.trim()) body.name = name.value.trim();
      if (duration.value.trim() !== "") body.duration_s = Number(duration.value);
      const last = await api.stream("/api/datasets/simulate/stream", body, {
        signal: ctx.signal,
        onLine: (doc) => {
          if (typeof doc.progress !== "number") return;
          bar.set(doc.progress);
          const s = Math.round((performance.now() - started) / 1000);
          // Each plant run of the build is a stage (air-path scenarios have two).
          const part = doc.stage > 1 ? `part ${doc.stage}, ` : "";
          progress.textContent = `Simulating… ${part}${Math.round(doc.progress * 100)} % (${s} s)`;
        },
      });
      ok = true;
      await onCreated(last.dataset);
    } catch (err) {
      showError(form, err);
    } finally {
      bar.finish(ok);
      bar.el.hidden = true;
      progress.textContent = "";
      submit.disabled = false;
      submit.replaceChildren(icon(ICONS.flask), "Simulate");
    }
  });
  return needs(SCOPE.run, card({ title: "Simulate a scenario", hint: "known truth", body: form }));
}

/* ---------- channel previews ---------- */

function sparkline(el, time, values, unit) {
  const t = theme();
  react(
    el,
    [
      {
        x: time,
        y: values,
        type: "scatter",
        mode: "lines",
        line: { color: t.accent, width: 1.2 },
        hovertemplate: `%{x:.2f} s: %{y:.4g} ${unit ?? ""}<extra></extra>`,
      },
    ],
    baseLayout({
      margin: { l: 4, r: 4, t: 2, b: 2 },
      xaxis: axis("", { visible: false }),
      yaxis: axis("", { visible: false }),
      showlegend: false,
    }),
    STATIC_CONFIG,
  );
}

/* ---------- column mapping ---------- */

/** Pick an estimator and the columns feeding its signals, then continue to the run form. */
async function mappingCard(ctx, dataset) {
  const host = h("div", { "data-mapping": "" });
  const channels = (dataset.channels ?? []).filter((c) => c.name !== dataset.time_column);
  let catalog = [];
  try {
    catalog = await estimators();
  } catch (err) {
    return card({ title: "Map columns", body: h("div", { class: "banner error" }, err.message) });
  }
  let suggested = [];
  if (dataset.scenario) {
    suggested =
      (await scenarios().catch(() => [])).find((s) => s.name === dataset.scenario)?.estimators ??
      [];
  }
  const estSelect = h(
    "select",
    { id: "map-estimator", name: "estimator" },
    Object.entries(KIND_TITLES).map(([kind, label]) =>
      h(
        "optgroup",
        { label },
        catalog
          .filter((e) => e.kind === kind)
          .map((e) =>
            h(
              "option",
              { value: e.name },
              `${e.name} — ${e.title}${suggested.includes(e.name) ? " (suggested)" : ""}`,
            ),
          ),
      ),
    ),
    catalog
      .filter((e) => !KIND_TITLES[e.kind])
      .map((e) => h("option", { value: e.name }, `${e.name} — ${e.title}`)),
  );
  estSelect.value =
    suggested[0] ?? (catalog.find((e) => e.name === "skf") ? "skf" : (catalog[0]?.name ?? ""));
  const roles = h("div", { class: "fields" });
  const go = h(
    "a",
    { class: "button primary", href: "#", "data-continue": "" },
    "Continue to new run →",
  );

  const channelSelect = (id, name, chosen, { optional = false } = {}) =>
    h(
      "select",
      { id, name },
      optional ? h("option", { value: "" }, "— none —") : null,
      channels.map((c) =>
        h("option", { value: c.name, selected: c.name === chosen }, withUnit(c.name, c.unit)),
      ),
    );

  const render = () => {
    const est = catalog.find((e) => e.name === estSelect.value);
    roles.replaceChildren();
    if (!est) return;
    if (est.kind === "table-filter") {
      const guess = guessTable(channels);
      roles.append(
        h(
          "div",
          { class: "field" },
          h("label", { for: "map-y" }, "Measured output (y)"),
          channelSelect("map-y", "signals.y", guess.y),
        ),
        h(
          "div",
          { class: "field" },
          h("label", { for: "map-ax0" }, "Table axis 1 (x)"),
          channelSelect("map-ax0", "axis.0", guess.axes[0]),
        ),
        h(
          "div",
          { class: "field" },
          h("label", { for: "map-ax1" }, "Table axis 2 (y)"),
          channelSelect("map-ax1", "axis.1", guess.axes[1], { optional: true }),
        ),
        h(
          "div",
          { class: "field" },
          h("label", { for: "map-ax2" }, "Table axis 3 (slices)"),
          channelSelect("map-ax2", "axis.2", null, { optional: true }),
        ),
      );
    } else {
      const taken = new Set();
      for (const role of rolesOf(est)) {
        const chosen = guessColumn(role, channels, taken);
        if (chosen) taken.add(chosen);
        const id = `map-role-${role.role}`;
        roles.append(
          h(
            "div",
            { class: "field" },
            h("label", { for: id }, `${role.role}${role.unit ? ` [${role.unit}]` : ""}`),
            channelSelect(id, `signals.${role.role}`, chosen),
            role.description ? h("div", { class: "help" }, role.description) : null,
          ),
        );
      }
      if (!rolesOf(est).length)
        roles.append(
          h(
            "p",
            { class: "help" },
            "This estimator reads its channels by name (set them on the next page).",
          ),
        );
    }
    update();
  };

  const update = () => {
    const signals = {};
    const axes = [];
    for (const sel of roles.querySelectorAll(CONTROL)) {
      if (sel.name.startsWith("signals.") && sel.value) signals[sel.name.slice(8)] = sel.value;
      if (sel.name.startsWith("axis.") && sel.value) axes.push(sel.value);
    }
    const q = new URLSearchParams({ dataset: String(dataset.id), estimator: estSelect.value });
    if (Object.keys(signals).length) q.set("signals", encodeSignals(signals));
    if (axes.length && needsTable(catalog.find((e) => e.name === estSelect.value)))
      q.set("axes", axes.join(","));
    go.href = `/runs/new?${q.toString().replaceAll("%2C", ",").replaceAll("%3A", ":")}`;
  };

  estSelect.addEventListener("change", render);
  roles.addEventListener("change", update);
  host.append(
    h("div", { class: "field" }, h("label", { for: "map-estimator" }, "Estimator"), estSelect),
    roles,
  );
  render();
  return card({
    title: "Map columns to an estimator",
    hint: "then set up the run",
    body: host,
    foot: [go],
  });
}
