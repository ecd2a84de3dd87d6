/**
 * The New run form's state: what the URL says (dataset, mode, estimators, signals, axes,
 * batch datasets) and what the form holds while it is open, plus the look-ups every part uses.
 *
 * `view` (built by index.js) carries the state, the catalog and datasets, the draft from
 * before a reload, and the form's shared actions: renderAll, syncUrl, updateSubmit, saveDraft,
 * selectTab. Each part of the form reads and writes `view.state` and calls those actions.
 */
import { decodeSignals } from "../../mapping.js";

/** What the form starts: a run per estimator, a sweep of one estimator, or a batch over datasets. */
export const MODES = Object.freeze([
  { value: "single", label: "Single run", title: "New run" },
  { value: "sweep", label: "Sweep", title: "New sweep" },
  { value: "batch", label: "Fleet batch", title: "New batch" },
]);

/** The state of a new form, from the URL's query (unknown datasets and estimators dropped). */
export function initialState(q, catalog, datasets) {
  const batchIds = (q.get("datasets") ?? "")
    .split(",")
    .map(Number)
    .filter((id) => datasets.some((d) => d.id === id));
  return {
    datasetId: Number(q.get("dataset")) || batchIds[0] || datasets[0]?.id || null,
    mode: MODES.some((m) => m.value === q.get("mode")) ? q.get("mode") : "single",
    batch: new Set(batchIds),
    sweep: { estimator: null, rows: [], samples: "", seed: "0", metric: "", order: "min" },
    chosen: new Set(
      (q.get("estimator") ?? "").split(",").filter((n) => catalog.some((e) => e.name === n)),
    ),
    signals: decodeSignals(q.get("signals")),
    axes: (q.get("axes") ?? "").split(",").filter(Boolean),
    dataset: null,
    preview: null,
    forms: new Map(),
    grid: null,
    tab: null,
    // The dataset's scenario setup (setup.js) and whether the form starts from it.
    setup: null,
    useSetup: q.get("setup") !== "off",
    switched: false,
  };
}

/** The ticked estimators, in catalog order. */
export function selectedEstimators(view) {
  return view.catalog.filter((e) => view.state.chosen.has(e.name));
}

/** The dataset's channels apart from its time column. */
export function channels(view) {
  const { dataset } = view.state;
  return (dataset?.channels ?? []).filter((c) => c.name !== dataset?.time_column);
}

/** An error shown next to the control of `field` (a dotted API path, e.g. "parameters.mu"). */
export function fieldError(field, message) {
  return Object.assign(new Error(message), { field });
}
