/**
 * The map editor's card (views/run/edit.js): the start button, the toolbar (lock, reset,
 * smooth, set, accept, reject, select all/none, undo, redo), the status lines, the host of
 * the cell grid and the save form. Only elements and their click handlers: what the buttons
 * do is the controller's `act(what)`.
 */
import { card, h } from "../../dom.js";
import { SCOPE } from "../../scopes.js";

/** The operations of the toolbar: [key in the edit log, button text, what it does]. */
export const TOOLS = Object.freeze([
  ["lock", "Lock", "Lock the selected cells (or unlock them when all are locked): L"],
  ["reset", "Reset", "Set the selected cells to the run's base map: R"],
  ["smooth", "Smooth", "3×3 binomial weighted average of each selected cell's neighbours: S"],
  ["accept", "Accept learned", "Keep the learned values (the selection, or every cell)"],
  ["reject", "Reject learned", "Back to the base map (the selection, or every cell)"],
]);

const HELP =
  "Click a cell on the map or in the grid; shift-click (or drag in the grid) for a rectangle, " +
  "ctrl-click to add or remove one. In the grid: arrows move, shift+arrows extend, space adds " +
  "or removes, Enter selects one, L / R / S lock, reset, smooth. Locked cells keep their value " +
  "through every operation.";

/**
 * @param {{unit: string, act: (what: string) => void}} opts  act: "start", "end", "save",
 *   "undo", "redo", "all", "none", or a TOOLS key / "set"
 */
export function editPanel({ unit, act }) {
  const button = (text, attrs, what, cls = "small") =>
    h("button", { type: "button", class: cls, ...attrs, onclick: () => act(what) }, text);
  const startButton = button("Edit this version", { "data-edit-start": "" }, "start");
  const availability = h("span", { class: "help", "data-edit-availability": "" });
  const setInput = h("input", {
    type: "number",
    step: "any",
    id: "edit-set-value",
    style: { width: "100px" },
    "aria-label": `Value to set the selected cells to (${unit})`,
  });
  const undoButton = button("Undo", { "data-edit-undo": "", title: "Ctrl+Z" }, "undo");
  const redoButton = button("Redo", { "data-edit-redo": "", title: "Ctrl+Y" }, "redo");
  const sep = () => h("span", { class: "edit-sep" });
  const toolbar = h(
    "div",
    { class: "row edit-toolbar", role: "toolbar", "aria-label": "Map editing" },
    TOOLS.map(([op, text, title]) => button(text, { title, "data-edit-op": op }, op)),
    sep(),
    setInput,
    h("span", { class: "help" }, unit),
    button("Set", { "data-edit-op": "set" }, "set"),
    sep(),
    button("Select all", { "data-edit-select-all": "" }, "all", "small ghost"),
    button("Clear selection", { "data-edit-clear": "" }, "none", "small ghost"),
    sep(),
    undoButton,
    redoButton,
  );
  const status = h("div", { class: "help", "aria-live": "polite", "data-edit-status": "" });
  const baseNote = h("div", { class: "help", "data-edit-base": "" });
  const sliceNote = h("div", { class: "help", "data-edit-slice": "" });
  const gridHost = h("div", { class: "values-grid edit-grid", "data-field": "values" });
  const nameInput = h("input", {
    type: "text",
    id: "edit-name",
    "data-field": "name",
    maxlength: "200",
  });
  const savedNote = h("div", { class: "help", "aria-live": "polite", "data-edit-saved": "" });
  // What the saved version comes from: the run, its version and the edits (edit.js fills it).
  const lineageNote = h("div", { class: "help", "data-edit-lineage": "" });
  const form = h(
    "form",
    {
      class: "row",
      novalidate: true,
      "aria-label": "Save the edited map as a labelled version",
      "data-needs": SCOPE.admin,
    },
    h("label", { for: "edit-name", style: { margin: 0 } }, "Version label"),
    h("div", { class: "field", style: { margin: 0, flex: 1 } }, nameInput),
    h(
      "button",
      {
        type: "submit",
        class: "small primary",
        "data-edit-save": "",
        title:
          "Store the edited map as a labelled map version (a base map: New run starts from it), " +
          "with the run, version and edits it comes from",
      },
      "Save as version…",
    ),
    button("Close editor", { "data-edit-discard": "" }, "end", "small ghost"),
    h("div", { class: "form-error", hidden: true, "data-form-error": "" }),
  );
  form.addEventListener("submit", (e) => {
    e.preventDefault();
    act("save");
  });
  const panel = h(
    "div",
    { class: "stack", hidden: true, "data-edit-panel": "", style: { marginTop: "12px" } },
    toolbar,
    status,
    baseNote,
    sliceNote,
    gridHost,
    h("p", { class: "help" }, HELP),
    lineageNote,
    form,
    savedNote,
  );
  const el = card({
    title: "Edit map",
    hint: "lock, reset, smooth, accept or reject cells; save as a labelled version",
    body: [h("div", { class: "row" }, startButton, availability), panel],
  });
  el.dataset.editCard = "";
  return {
    el,
    panel,
    form,
    startButton,
    availability,
    setInput,
    undoButton,
    redoButton,
    status,
    baseNote,
    sliceNote,
    gridHost,
    nameInput,
    lineageNote,
    savedNote,
  };
}
