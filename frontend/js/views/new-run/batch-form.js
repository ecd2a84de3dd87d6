/**
 * A fleet batch (?mode=batch&datasets=1,2,3): the datasets it runs one configuration over,
 * one run each, merged into one map. The dataset select above then only lends the channels,
 * signals and grid.
 */
import { SELECT } from "../../constants.js";
import { fmtInt, h } from "../../dom.js";
import { fieldError } from "./state.js";

/** The batch's dataset check boxes (hidden outside batch mode). */
export function batchPicker() {
  const list = h("div", { class: "batch-datasets" });
  const el = h(
    "div",
    {
      class: "field",
      "data-batch-datasets": "",
      "data-field": "dataset_ids",
      role: "group",
      "aria-labelledby": "batch-datasets-label",
    },
    h(
      "div",
      { class: "label", id: "batch-datasets-label" },
      "Datasets of the batch — one run each, merged into one map",
    ),
    list,
  );
  return { el, list };
}

export function renderBatch(view) {
  const { state, batch } = view;
  const on = state.mode === "batch";
  batch.el.hidden = !on;
  view.datasetPicker.label.textContent = on ? "Channels, signals and grid from" : "Dataset";
  if (!on) return;
  batch.list.replaceChildren(...view.datasets.map((d) => batchChoice(view, d)));
}

function batchChoice(view, d) {
  const { state } = view;
  const onchange = (e) => {
    if (e.target.checked) state.batch.add(d.id);
    else state.batch.delete(d.id);
    view.syncUrl();
    view.updateSubmit();
  };
  return h(
    "div",
    { class: "field" },
    h(
      "label",
      { class: "check", for: `batch-ds-${d.id}` },
      h("input", {
        type: "checkbox",
        id: `batch-ds-${d.id}`,
        value: String(d.id),
        "data-batch-dataset": "",
        checked: state.batch.has(d.id),
        onchange,
      }),
      h("span", {}, `#${d.id} ${d.name}`, h("span", { class: "sub" }, ` · ${fmtInt(d.rows)} rows`)),
    ),
  );
}

/**
 * The datasets of the batch (by id); each checkbox is tagged with its place so
 * "dataset_ids[k]" errors find it.
 */
export function readBatch(view) {
  const { list } = view.batch;
  const ids = view.datasets
    .filter((d) => view.state.batch.has(d.id))
    .map((d) => d.id)
    .sort((a, b) => a - b);
  for (const el of list.querySelectorAll("[data-batch-dataset]")) el.removeAttribute("data-field");
  ids.forEach((dsId, k) =>
    list
      .querySelector(SELECT.id(`batch-ds-${dsId}`))
      ?.setAttribute("data-field", `dataset_ids.${k}`),
  );
  if (ids.length < 2) {
    throw fieldError(
      "dataset_ids",
      "Pick at least two datasets: a batch merges several vehicles' maps.",
    );
  }
  return ids;
}
