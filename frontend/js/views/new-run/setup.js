/**
 * Where the form's starting values come from besides the catalog's defaults:
 *
 * - the scenario's setup of a simulated dataset (GET /api/datasets/{id}/setup: per estimator
 *   the scenario's grid, signals and settings with this realisation's drawn constants), used
 *   while "Use the scenario's setup" is on (the default for a simulated dataset), so a run
 *   on known truth is scored against it (the truth's grid) and starts from the paper's
 *   settings of that scenario;
 * - a previous run ("Run again…", /runs/new?from=RUN_ID): its dataset, estimator, signals,
 *   grid and configuration, ready to change.
 *
 * A previous run wins over the scenario's setup; the toggle turns both off.
 */
import { api } from "../../api.js";
import { h } from "../../dom.js";

/** Keys of a run's config that the run options hold, not the estimator's form. */
const SERVICE_KEYS = new Set(["pace", "version_every", "gates", "locked", "raster"]);

/** The setup of the state's dataset (null for none, or when the API has no such route). */
export async function fetchSetup(view) {
  const { state, ctx } = view;
  state.setup = await api
    .get(`/api/datasets/${state.datasetId}/setup`, { signal: ctx.signal })
    .catch(() => null);
  return state.setup;
}

/** Whether estimator `name` applies to the dataset's scenario (always, for an uploaded log). */
export function applies(view, name) {
  const setup = view.state.setup;
  if (!setup?.scenario) return true;
  return name in (setup.estimators ?? {});
}

/**
 * What estimator `name` starts from on the state's dataset, or null (catalog defaults):
 * {table, signals, config, source} with `source` naming where it comes from.
 */
export function startOf(view, name) {
  const { state } = view;
  const run = view.fromRun;
  if (run && run.estimator === name && run.dataset_id === state.datasetId) {
    const config = Object.fromEntries(
      Object.entries(run.config ?? {}).filter(([k]) => !SERVICE_KEYS.has(k)),
    );
    return { table: run.table, signals: run.signals ?? {}, config, source: `run #${run.id}` };
  }
  if (!state.useSetup) return null;
  const entry = state.setup?.estimators?.[name];
  if (!entry) return null;
  return { ...entry, source: `scenario ${state.setup.scenario}` };
}

/** The grid of the first chosen estimator with one, as a grid-editor snapshot (or null). */
export function startGrid(view, ests) {
  for (const e of ests) {
    const table = startOf(view, e.name)?.table;
    if (!table?.axes?.length) continue;
    return {
      axes: table.axes.map((a) => ({
        name: a.name,
        unit: a.unit ?? "",
        text: a.breakpoints.join(", "),
        n: a.breakpoints.length,
      })),
      start: "constant",
      values: null,
      locked: [],
      slice: 0,
    };
  }
  return null;
}

/** The column a chosen estimator's start gives signal role `role` (or undefined). */
export function startSignal(view, ests, role) {
  for (const e of ests) {
    const column = startOf(view, e.name)?.signals?.[role];
    if (column) return column;
  }
  return undefined;
}

/**
 * The "Use the scenario's setup" switch (shown for a simulated dataset): turning it starts
 * the signals, grid and configuration afresh from the setup or from the catalog's defaults.
 */
export function renderSetupToggle(view) {
  const { state } = view;
  const host = view.datasetPicker.setupHost;
  const setup = state.setup;
  const run = view.fromRun;
  const again = run
    ? h(
        "div",
        { class: "banner", "data-from-run": String(run.id) },
        `Starting from run #${run.id} (${run.estimator}): its signals, grid and configuration ` +
          "fill the form; change what you like.",
      )
    : null;
  if (!setup?.scenario || !Object.keys(setup.estimators ?? {}).length) {
    host.replaceChildren(...(again ? [again] : []));
    return;
  }
  const box = h("input", {
    type: "checkbox",
    id: "run-use-setup",
    name: "use_setup",
    checked: state.useSetup,
  });
  box.addEventListener("change", () => {
    state.useSetup = box.checked;
    view.fromRun = null;
    state.signals = {};
    state.axes = [];
    state.forms = new Map();
    state.grid?.destroy();
    state.grid = null;
    view.renderAll();
    view.syncUrl();
  });
  const seed = setup.seed === null || setup.seed === undefined ? "" : `, seed ${setup.seed}`;
  const mismatch = setup.mismatch ? `, ${setup.mismatch} mismatch` : "";
  host.replaceChildren(
    ...(again ? [again] : []),
    h(
      "div",
      { class: "field", "data-use-setup": "" },
      h("label", { class: "check", for: box.id }, box, "Use the scenario's setup"),
      h(
        "div",
        { class: "help" },
        `Simulated from ${setup.scenario}${seed}${mismatch}: its grid, signals and estimator ` +
          "settings (with this realisation's model constants) fill the form, so the run is " +
          "scored against the known truth. Off: the estimators' defaults and a grid fitted " +
          "to the data.",
      ),
    ),
  );
}
