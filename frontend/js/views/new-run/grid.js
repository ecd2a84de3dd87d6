/**
 * Section 4: the table grid (axes, breakpoints, start values or a base map) for estimators
 * that adapt a table, fitted to the dataset's preview, or taken from an ECU map
 * (ecu-prefill.js). Other estimators hide the section.
 */
import { gridEditor } from "../../grid-editor.js";
import { guessTable, needsTable } from "../../mapping.js";
import { prefillGrid } from "./ecu-prefill.js";
import { startGrid } from "./setup.js";
import { channels, selectedEstimators } from "./state.js";

/** Show the grid editor when a chosen estimator needs a table; a new one per dataset. */
export function renderTable(view) {
  const { state, draft } = view;
  const show = selectedEstimators(view).some(needsTable);
  view.hosts.tableSection.hidden = !show;
  if (!show) return;
  const chans = channels(view);
  // The scenario's (or a reused run's) grid, else axes guessed from the channel names.
  const start = startGrid(view, selectedEstimators(view));
  const wanted = state.axes.length
    ? state.axes
    : (start?.axes.map((a) => a.name) ?? guessTable(chans).axes);
  const startKey = start ? JSON.stringify(start.axes) : "";
  if (state.grid && state.grid.datasetId === state.datasetId && state.grid.startKey === startKey)
    return state.grid.redraw();
  state.grid?.destroy();
  const savedAxes = draft?.grid?.axes?.map((a) => a.name);
  // A column just picked for an ECU axis, else the draft of a reload, else the ECU's map.
  const prefill = prefillGrid(view);
  const fromEcu =
    prefill &&
    sameNames(
      prefill.axes.map((a) => a.name),
      wanted,
    )
      ? prefill
      : null;
  const fromStart =
    start &&
    sameNames(
      start.axes.map((a) => a.name),
      wanted,
    )
      ? start
      : null;
  const saved =
    (view.ecu?.pending && fromEcu) ||
    (draft?.grid && sameNames(savedAxes, wanted) ? draft.grid : null) ||
    fromEcu ||
    fromStart;
  if (view.ecu) view.ecu.pending = null;
  if (draft) draft.grid = null;
  const g = gridEditor({
    channels: chans,
    preview: state.preview,
    axes: wanted,
    baseMaps: view.baseMaps,
    saved,
    onChange: () => {
      view.syncUrl();
      view.saveDraft();
    },
  });
  g.datasetId = state.datasetId;
  g.startKey = startKey;
  state.grid = g;
  view.hosts.table.replaceChildren(g.el);
  return undefined;
}

function sameNames(a, b) {
  return Array.isArray(a) && a.length === b.length && a.every((x, i) => x === b[i]);
}
