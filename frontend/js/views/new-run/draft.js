/**
 * The draft: the parts of the form the URL does not hold (breakpoints, start map, config
 * values, pace, cadence, gates, sweep rows) kept in sessionStorage, so a reload shows the
 * form as it was. A draft belongs to one dataset; each part is used once, then dropped.
 */
import { SELECT, STORAGE } from "../../constants.js";
import { debounce } from "../../dom.js";

/** Controls whose values a draft keeps (file inputs cannot be restored). */
const DRAFT_CONTROLS = "input:not([type=file]), select, textarea";
const DRAFT_SAVE_MS = 120;

function loadDraft() {
  try {
    return JSON.parse(sessionStorage.getItem(STORAGE.newRunDraft) ?? "null");
  } catch {
    return null;
  }
}

/**
 * The saved draft of this form when it is for the state's dataset (else null); its sweep
 * rows go straight into the state. A sweep or batch runs one estimator: only the first stays.
 */
export function takeDraft(state) {
  const saved = loadDraft();
  const draft = saved && saved.datasetId === state.datasetId ? saved : null;
  if (draft?.sweep && typeof draft.sweep === "object" && Array.isArray(draft.sweep.rows)) {
    const rows = draft.sweep.rows.filter((r) => r && typeof r.key === "string");
    state.sweep = { ...state.sweep, ...draft.sweep, rows };
  }
  if (state.mode !== "single" && state.chosen.size > 1) {
    state.chosen = new Set([[...state.chosen][0]]);
  }
  return draft;
}

/** {id: value | checked} of the controls in `container`. */
export function controlValues(container) {
  const out = {};
  for (const el of container.querySelectorAll(DRAFT_CONTROLS)) {
    if (!el.id) continue;
    out[el.id] = el.type === "checkbox" || el.type === "radio" ? el.checked : el.value;
  }
  return out;
}

/** Put saved control values back; a "change" event lets dependent parts (switches) follow. */
export function restoreControls(container, values) {
  for (const [id, value] of Object.entries(values ?? {})) {
    const el = container.querySelector(SELECT.id(id));
    if (!el) continue;
    if (el.type === "checkbox" || el.type === "radio") el.checked = Boolean(value);
    else el.value = String(value);
    el.dispatchEvent(new Event("change"));
  }
}

function draftNow(view) {
  const { state } = view;
  const config = {};
  for (const [name, f] of state.forms) config[name] = controlValues(f.panel);
  return {
    datasetId: state.datasetId,
    grid: state.grid?.snapshot() ?? null,
    config,
    options: controlValues(view.options.el),
    gates: view.options.gates.list.map((g) => ({ ...g })),
    tab: state.tab,
    sweep: state.sweep,
  };
}

/**
 * Keep the draft of `view.form` up to date: saved shortly after any input, change or click,
 * and when the page is hidden. Returns {save, forget, stop}: forget() drops the draft (the
 * form was submitted), stop() ends the saving (the view is left).
 */
export function draftKeeper(view) {
  const save = () => {
    if (view.ctx.signal.aborted) return;
    try {
      sessionStorage.setItem(STORAGE.newRunDraft, JSON.stringify(draftNow(view)));
    } catch {
      /* storage full or disabled: the form simply starts afresh after a reload */
    }
  };
  const saveSoon = debounce(save, DRAFT_SAVE_MS);
  for (const type of ["input", "change", "click"]) view.form.addEventListener(type, saveSoon);
  window.addEventListener("pagehide", save);
  const stop = () => window.removeEventListener("pagehide", save);
  const forget = () => {
    sessionStorage.removeItem(STORAGE.newRunDraft);
    stop();
  };
  return { save, forget, stop };
}
