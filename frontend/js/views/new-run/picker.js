/**
 * Sections 1–3 of the form: the dataset (with its rows, rate and channels), the estimators
 * (grouped by kind, the dataset's scenario's suggestions marked, each with its description and
 * paper) and the columns that feed the chosen estimators' signals.
 */
import { api } from "../../api.js";
import { fmt, fmtDuration, fmtInt, h, withUnit } from "../../dom.js";
import { guessColumn, guessTable, KIND_TITLES, rolesOf } from "../../mapping.js";
import { loadTemplate } from "./ecu-prefill.js";
import { applies, fetchSetup, renderSetupToggle, startSignal } from "./setup.js";
import { channels, selectedEstimators } from "./state.js";

/* ---------- 1. dataset ---------- */

/**
 * The dataset select; picking another dataset starts its signals and axes afresh, and unticks
 * the estimators its scenario does not apply to.
 */
export function datasetPicker(view) {
  const { state } = view;
  const select = h(
    "select",
    { id: "run-dataset", name: "dataset_id" },
    view.datasets.map((d) =>
      h(
        "option",
        { value: String(d.id), selected: d.id === state.datasetId },
        `#${d.id} ${d.name} (${d.source})`,
      ),
    ),
  );
  const info = h("div", { class: "help" });
  const setupHost = h("div", { "data-setup-host": "" });
  const label = h("label", { for: "run-dataset" }, "Dataset");
  select.addEventListener("change", async () => {
    state.datasetId = Number(select.value);
    state.signals = {};
    state.axes = [];
    state.useSetup = true;
    view.fromRun = null;
    state.switched = true;
    await loadDataset(view);
    view.syncUrl();
  });
  return {
    el: h("div", {}, h("div", { class: "field" }, label, select, info), setupHost),
    label,
    info,
    setupHost,
    select,
  };
}

/**
 * Fetch the chosen dataset and its preview (the grid editor fits its breakpoints to it),
 * suggest an estimator when none is chosen, and draw the form.
 */
export async function loadDataset(view) {
  const { state, ctx } = view;
  state.loading = true;
  state.dataset =
    view.datasets.find((d) => d.id === state.datasetId) ??
    (await api.get(`/api/datasets/${state.datasetId}`));
  const d = state.dataset;
  view.datasetPicker.info.textContent =
    `${fmtInt(d.rows)} rows at ${fmt(d.rate_hz, 3)} Hz (${fmtDuration(d.duration_s)}); channels: ` +
    (d.channels ?? []).map((c) => withUnit(c.name, c.unit)).join(", ");
  state.preview = await api
    .get(`/api/datasets/${d.id}/preview`, { query: { points: 400 }, signal: ctx.signal })
    .catch(() => null);
  await loadTemplate(view);
  await fetchSetup(view);
  if (state.switched) {
    // Another dataset: keep only the estimators its scenario applies to (none kept for an
    // uploaded log after a simulated one: the suggestion below starts afresh).
    state.switched = false;
    state.chosen = new Set(
      [...state.chosen].filter((n) => applies(view, n) && (d.scenario || !view.lastScenario)),
    );
  }
  view.lastScenario = d.scenario ?? null;
  renderSetupToggle(view);
  if (!state.chosen.size) {
    const first =
      suggestedFor(view, d).find((n) => view.catalog.some((e) => e.name === n)) ??
      (view.catalog.some((e) => e.name === "skf") && applies(view, "skf") ? "skf" : null) ??
      firstApplying(view) ??
      view.catalog[0]?.name;
    if (first) state.chosen.add(first);
  }
  state.loading = false;
  renderEstimators(view);
  view.renderAll();
}

/** The estimators the dataset's scenario suggests (none for an uploaded log). */
function suggestedFor(view, dataset) {
  return view.scenarioList.find((s) => s.name === dataset?.scenario)?.estimators ?? [];
}

/** The first estimator of the catalog the dataset's scenario applies to, else null. */
function firstApplying(view) {
  return view.catalog.find((e) => applies(view, e.name))?.name ?? null;
}

/* ---------- 2. estimators ---------- */

/** Check boxes (radio buttons in a sweep or batch, which run one estimator) grouped by kind. */
export function renderEstimators(view) {
  const { catalog, state } = view;
  const suggested = new Set(suggestedFor(view, state.dataset));
  const groups = Object.entries(KIND_TITLES).map(([kind, label]) => [
    label,
    catalog.filter((e) => e.kind === kind),
  ]);
  const other = catalog.filter((e) => !KIND_TITLES[e.kind]);
  if (other.length) groups.push(["Other", other]);
  const help =
    state.mode === "single"
      ? "Tick several to run the same data through each and compare them."
      : `A ${state.mode === "sweep" ? "sweep" : "batch"} runs one estimator: pick it.`;
  view.hosts.estimators.replaceChildren(
    h("p", { class: "help", style: { marginTop: 0 } }, help),
    ...groups
      .filter(([, list]) => list.length)
      .map(([label, list]) =>
        h(
          "fieldset",
          { style: { border: 0, padding: 0, margin: "0 0 12px" } },
          h("legend", { style: { padding: 0, marginBottom: "8px" } }, h("h3", {}, label)),
          h(
            "div",
            { class: "est-grid" },
            list.map((e) => estimatorChoice(view, e, suggested)),
          ),
        ),
      ),
  );
}

function estimatorChoice(view, e, suggested) {
  const { state } = view;
  const fits = applies(view, e.name);
  const onchange = (ev) => {
    // A sweep or batch runs one estimator: the boxes become radio buttons.
    if (state.mode !== "single") state.chosen = new Set([e.name]);
    else if (ev.target.checked) state.chosen.add(e.name);
    else state.chosen.delete(e.name);
    view.renderAll();
    view.syncUrl();
  };
  return h(
    "label",
    {
      class: `est${suggested.has(e.name) ? " suggested" : ""}`,
      for: `est-${e.name}`,
      dataset: { estimator: e.name, applies: String(fits) },
    },
    h("input", {
      type: state.mode === "single" ? "checkbox" : "radio",
      id: `est-${e.name}`,
      name: "estimator",
      value: e.name,
      checked: state.chosen.has(e.name),
      onchange,
    }),
    h("div", { class: "t" }, e.title ?? e.name, h("code", { class: "tag" }, e.name)),
    h("div", { class: "d" }, e.description),
    e.paper ? h("div", { class: "p", title: e.paper }, shortPaper(e.paper)) : null,
    fits ? null : h("div", { class: "help" }, `Not for ${state.setup?.scenario ?? "this"} data.`),
  );
}

/* ---------- 3. signals ---------- */

/** A column per signal role of the chosen estimators, guessed from the names until picked. */
export function renderSignals(view) {
  const { state } = view;
  const chans = channels(view);
  const ests = selectedEstimators(view);
  const roles = new Map();
  for (const e of ests) for (const r of rolesOf(e)) if (!roles.has(r.role)) roles.set(r.role, r);
  if (ests.some((e) => e.kind === "table-filter") && !roles.has("y")) {
    roles.set("y", { role: "y", description: "Measured table output", unit: "" });
  }
  const taken = new Set();
  const guessY = guessTable(chans).y;
  const fields = [...roles.values()].map((r) => {
    let chosen =
      state.signals[r.role] ??
      startSignal(view, ests, r.role) ??
      (r.role === "y" ? guessY : guessColumn(r, chans, taken));
    if (!chans.some((c) => c.name === chosen)) chosen = guessColumn(r, chans, taken);
    if (chosen) taken.add(chosen);
    state.signals[r.role] = chosen;
    return signalField(view, r, chans, chosen);
  });
  const empty = ests.length
    ? "The selected estimators read their channels from the configuration below."
    : "Pick an estimator first.";
  view.hosts.signals.replaceChildren(
    fields.length ? h("div", { class: "fields" }, fields) : h("p", { class: "help" }, empty),
  );
}

function signalField(view, r, chans, chosen) {
  const id = `sig-${r.role}`;
  const sel = h(
    "select",
    { id, name: `signals.${r.role}` },
    chans.map((c) =>
      h("option", { value: c.name, selected: c.name === chosen }, withUnit(c.name, c.unit)),
    ),
  );
  sel.addEventListener("change", () => {
    view.state.signals[r.role] = sel.value;
    view.syncUrl();
  });
  return h(
    "div",
    { class: "field" },
    h(
      "label",
      { for: id },
      r.role === "y" ? "Measured output y" : r.role,
      r.unit ? ` [${r.unit}]` : "",
    ),
    sel,
    r.description ? h("div", { class: "help" }, r.description) : null,
  );
}

/**
 * "Guardiola, Pla, … (2014), Control Eng. Practice — the SKF paper" →
 * "Guardiola et al. (2014) · the SKF paper".
 */
export function shortPaper(paper) {
  const m = /^([^,(&]+)[^(]*\((\d{4})\)/.exec(paper);
  if (!m) return paper.length > 80 ? `${paper.slice(0, 77)}…` : paper;
  const many = /,|&| and /.test(paper.slice(0, paper.indexOf("(")));
  const nick = /—\s*(.+)$/.exec(paper)?.[1];
  return `${m[1].trim()}${many ? " et al." : ""} (${m[2]})${nick ? ` · ${nick}` : ""}`;
}
