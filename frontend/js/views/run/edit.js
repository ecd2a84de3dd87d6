/**
 * Editing a finished run's map like a calibration tool: pick cells on the map plot (click,
 * shift-click for a rectangle, ctrl-click to add) or in the cell grid (edit-grid.js: also
 * drag and the keyboard), then lock them, reset them to the run's base map, smooth them, set
 * them to a value, accept or reject the learned values; undo and redo (buttons, Ctrl+Z /
 * Ctrl+Y); save the result as a new labelled map version with its lineage. A labelled version
 * of an edited map is a base map (POST /api/base-maps with `values`, `edits`, source "edit"):
 * a run's own versions are the steps it estimated, so an edit is stored beside them, with the
 * run, version and edit log as its lineage, and New run starts from it (docs/dashboard.md).
 *
 * The operations are the pure functions of map-edit-ops.js; the card is edit-panel.js. While
 * an edit is open the map plot shows the edited values with the selection outlined, and the
 * versions timeline is held on the version being edited. The editor hooks itself into the
 * timeline's onShow/onList and the map plot's plotly_click, so maps.js and timeline.js need
 * no change for it.
 */
import { api, showError } from "../../api.js";
import { RUN_DONE } from "../../constants.js";
import { fmt, toast, withUnit } from "../../dom.js";
import { nearestIndex } from "../../grid-math.js";
import * as ops from "../../map-edit-ops.js";
import { cellGrid } from "./edit-grid.js";
import { editPanel } from "./edit-panel.js";

/**
 * The editor of run view `v`, its card placed under the versions timeline. Returns
 * {card, active, redraw(), destroy()}; `active` while an edit is open.
 */
export function runEdit(v) {
  const ed = {
    active: false,
    version: null,
    doc: null,
    axes: [],
    shape: [],
    state: null,
    history: null,
    sel: new Set(),
    anchor: null,
    focus: 0,
  };
  const ui = editPanel({ unit: v.outputUnit || "-", act });
  const grid = cellGrid(ui.gridHost, {
    label: `Cells of the map, ${withUnit(v.outputName, v.outputUnit || "-")}`,
    selection: () => ed.sel,
    pick,
    select: (cells) => select(cells === "all" ? all() : cells),
    tool,
    focus: (k) => {
      ed.focus = k;
      paint();
    },
  });
  const tl = v.timeline;
  const name = () => `v${ed.version?.number ?? ed.version?.step ?? "?"}`;

  function act(what) {
    if (what === "start") start();
    else if (what === "end") end();
    else if (what === "save") save();
    else if (what === "undo") step(ops.undo);
    else if (what === "redo") step(ops.redo);
    else if (what === "all") select(all());
    else if (what === "none") select([]);
    else tool(what);
  }

  /* ---------- the timeline: held while editing ---------- */
  const shown = tl.onShow;
  tl.onShow = (doc, version, how) => (ed.active ? redraw() : shown(doc, version, how));
  const listed = tl.onList;
  tl.onList = (versions) => {
    listed?.(versions);
    availability();
  };

  function availability() {
    const done = RUN_DONE.has(v.s.run.status);
    const version = tl.current();
    ui.startButton.disabled = ed.active || !done || !version;
    ui.availability.textContent = ed.active
      ? `Editing ${name()}; the timeline is held until the editor is closed.`
      : !done
        ? "Editing opens when the run has finished."
        : version
          ? `Edits start from the version shown (v${version.number ?? "?"}); scrub the timeline to pick another.`
          : "The run stored no map version.";
  }

  /* ---------- starting and ending ---------- */
  async function start() {
    const version = tl.current();
    if (ed.active || !version || !RUN_DONE.has(v.s.run.status)) return;
    let doc;
    let base;
    try {
      doc = version.doc ?? (await tl.doc(version));
      base = await baseMap(v, doc);
    } catch (err) {
      showError(ui.el, err);
      return;
    }
    const shape = doc.axes.map((a) => a.breakpoints.length);
    const learned = ops.flatten(doc.values);
    Object.assign(ed, {
      version,
      doc,
      axes: doc.axes,
      shape,
      state: ops.startEdit({ shape, learned, base: base.values }),
      history: ops.history(ops.historyLimit(learned.length)),
      sel: new Set(),
      anchor: null,
      focus: 0,
      active: true,
    });
    ui.baseNote.textContent = `Base map (Reset, Reject): ${base.text}.`;
    ui.nameInput.value = `${v.s.run.name || `run ${v.id}`} ${name()} edited`;
    ui.savedNote.textContent = "";
    ui.panel.hidden = false;
    tl.stopPlay();
    tl.slider.disabled = true;
    tl.playButton.disabled = true;
    tl.note.hidden = false;
    tl.note.textContent = `editing ${name()}`;
    availability();
    attachPlot();
    document.addEventListener("keydown", onKeys);
    renderGrid();
    refresh();
    grid.focus();
  }

  /** Close the edit (unsaved edits are dropped); `leaving`: the view is going away. */
  function end({ leaving = false } = {}) {
    if (!ed.active) return;
    ed.active = false;
    detachPlot();
    document.removeEventListener("keydown", onKeys);
    if (leaving) return;
    ui.panel.hidden = true;
    tl.slider.disabled = tl.versions.length === 0;
    tl.playButton.disabled = tl.versions.length < 2;
    availability();
    tl.reshow();
    ui.startButton.focus();
  }

  /* ---------- operations ---------- */
  const all = () => ed.state.values.map((_, k) => k);
  const selected = () => [...ed.sel].sort((a, b) => a - b);

  function tool(op) {
    if (!ed.active) return;
    const cells = selected();
    const none = !cells.length;
    if (none && op !== "accept" && op !== "reject") {
      ui.status.textContent = "Select cells first.";
      return;
    }
    const s = ed.state;
    const typed = ui.setInput.value === "" ? NaN : Number(ui.setInput.value);
    const after = {
      lock: () => ops.toggleLock(s, cells),
      reset: () => ops.resetCells(s, cells),
      smooth: () => ops.smooth(s, cells),
      accept: () => ops.acceptCells(s, none ? null : cells),
      reject: () => ops.rejectCells(s, none ? null : cells),
      set: () => ops.setCells(s, cells, typed),
    }[op]?.();
    if (!after || (op === "set" && after === s)) {
      ui.status.textContent = "Type a finite value to set the selected (unlocked) cells to.";
      return;
    }
    ed.history = ops.record(ed.history, s, after);
    ed.state = after;
    refresh();
  }

  function step(how) {
    if (!ed.active) return;
    const { history, state } = how(ed.history, ed.state);
    ed.history = history;
    ed.state = state;
    refresh();
  }

  /** Ctrl+Z / Ctrl+Y (and Ctrl+Shift+Z) anywhere but in a text field, while an edit is open. */
  function onKeys(e) {
    if (!(e.ctrlKey || e.metaKey) || e.altKey) return;
    if (e.target?.matches?.("input, textarea, select, [contenteditable]")) return;
    const key = e.key.toLowerCase();
    if (key === "z" && !e.shiftKey) {
      e.preventDefault();
      step(ops.undo);
    } else if (key === "y" || (key === "z" && e.shiftKey)) {
      e.preventDefault();
      step(ops.redo);
    }
  }

  /* ---------- selection ---------- */
  function select(cells, { anchor = null } = {}) {
    if (!ed.active) return;
    ed.sel = new Set(cells);
    if (anchor !== null) ed.anchor = anchor;
    refresh();
  }

  /**
   * A cell picked: alone, added or removed (toggle), or the rectangle from the anchor (shift;
   * `from` is the anchor when there is none yet, e.g. the cell a shift+arrow left).
   */
  function pick(k, { shift = false, toggle = false, from = null } = {}) {
    ed.focus = k;
    if (shift && ed.anchor === null && from !== null) ed.anchor = from;
    if (shift && ed.anchor !== null) {
      const box = ops.rectangle(
        ops.indexOf(ed.anchor, ed.shape),
        ops.indexOf(k, ed.shape),
        ed.shape,
      );
      select(toggle ? [...ed.sel, ...box] : box);
    } else if (toggle) {
      const next = new Set(ed.sel);
      if (next.has(k)) next.delete(k);
      else next.add(k);
      select(next, { anchor: k });
    } else {
      select([k], { anchor: k });
    }
  }

  /* ---------- the map plot ---------- */
  let plotEl = null;
  const plotCard = () => plotEl?.closest(".card");

  function attachPlot() {
    plotEl = v.root.querySelector('[data-plot="map"]');
    plotEl?.on?.("plotly_click", onPlotClick);
    plotCard()?.addEventListener("input", onSliceMoved);
  }

  function detachPlot() {
    plotEl?.removeListener?.("plotly_click", onPlotClick);
    plotCard()?.removeEventListener("input", onSliceMoved);
    plotEl = null;
  }

  /** The slice indices of the map plot's further axes (its sliders), [] for 1-D and 2-D. */
  function sliceIndex() {
    const inputs = plotCard()?.querySelectorAll("input[data-slice-axis]") ?? [];
    const idx = [...inputs].map((i) => Number(i.value) || 0);
    return ed.shape.slice(2).map((n, k) => Math.min(n - 1, idx[k] ?? 0));
  }

  /** A click on the map: the cell at the breakpoints nearest to it, in the slice shown. */
  function onPlotClick(ev) {
    const p = ev?.points?.[0];
    if (!ed.active || !p || typeof p.x !== "number") return;
    const bp = ed.axes.map((a) => a.breakpoints);
    const idx =
      ed.shape.length === 1
        ? [nearestIndex(bp[0], p.x)]
        : [nearestIndex(bp[0], p.x), nearestIndex(bp[1], p.y), ...sliceIndex()];
    const e = ev.event ?? {};
    pick(ops.flatIndex(idx, ed.shape), { shift: e.shiftKey, toggle: e.ctrlKey || e.metaKey });
  }

  function onSliceMoved(e) {
    if (ed.active && e.target?.matches?.("input[data-slice-axis]")) renderGrid();
  }

  /** Draw the edited map on the run's map plot, the selection outlined (the map only). */
  function redraw() {
    if (!ed.active) return;
    v.maps.draw(
      {
        axes: ed.axes,
        values: nested(ed.state.values, ed.shape),
        variances: ed.doc.variances,
        visits: ed.doc.visits,
        trail: null,
        activeCell: null,
        outlines: selected().map((k) => ops.indexOf(k, ed.shape)),
      },
      { variance: false },
    );
  }

  /* ---------- the grid and the status ---------- */
  function renderGrid() {
    const tail = sliceIndex();
    grid.render({ shape: ed.shape, axes: ed.axes, tail });
    ui.sliceNote.textContent = tail.length
      ? `Slice at ${ed.axes
          .slice(2)
          .map((a, k) => `${a.name} = ${fmt(a.breakpoints[tail[k]])} ${a.unit ?? ""}`.trim())
          .join(", ")} (the map's slider picks the slice).`
      : "";
    paint();
  }

  function paint() {
    if (ed.active) grid.paint(ed.state, ed.sel, ed.focus);
  }

  function refresh() {
    if (!ed.active) return;
    paint();
    const s = ed.state;
    const hist = ed.history;
    ui.lineageNote.textContent =
      `Lineage of the saved version: run ${v.id}, ${name()}` +
      `${ed.version?.label ? ` “${ed.version.label}”` : ""}, ${s.log.length} edit(s)` +
      (s.log.length ? ` (${s.log.map((e) => e.op).join(", ")})` : "") +
      ".";
    ui.status.textContent =
      `${ed.sel.size} selected · ${s.locked.size} locked · ` +
      `${ops.editedCells(s).length} changed from ${name()} · ${s.log.length} edit(s), ` +
      `${hist.past.length} to undo (at most ${hist.limit}), ${hist.future.length} to redo`;
    ui.undoButton.disabled = !hist.past.length;
    ui.redoButton.disabled = !hist.future.length;
    redraw();
  }

  /* ---------- saving ---------- */
  async function save() {
    if (!ed.active) return;
    for (const n of ui.el.querySelectorAll(".field-error")) n.remove();
    ui.form.querySelector("[data-form-error]").hidden = true;
    const s = ed.state;
    const body = {
      run_id: v.id,
      version_id: ed.version.id,
      name: ui.nameInput.value.trim() || undefined,
      values: nested(s.values, ed.shape),
      edits: s.log,
      source: "edit",
    };
    try {
      const map = await api.post("/api/base-maps", body);
      ui.savedNote.textContent =
        `Saved version “${map.name}” (base map #${map.id}; lineage: run ${v.id}, ${name()}, ` +
        `${s.log.length} edit(s)); New run offers it under “Import a base map”.`;
      ui.savedNote.dataset.editSaved = String(map.id);
      toast(`Saved version “${map.name}” (base map #${map.id}).`);
    } catch (err) {
      showError(ui.el, err);
    }
  }

  const onAbort = () => end({ leaving: true });
  v.ctx.signal?.addEventListener("abort", onAbort);
  tl.el.closest(".card")?.after(ui.el); // under the versions timeline it edits from
  availability();

  return {
    card: ui.el,
    get active() {
      return ed.active;
    },
    redraw,
    destroy() {
      end({ leaving: true });
      tl.onShow = shown;
      tl.onList = listed;
      v.ctx.signal?.removeEventListener("abort", onAbort);
    },
  };
}

/** Flat values as the API's nested lists, NaN as null. */
function nested(flat, shape) {
  return ops.nest(
    flat.map((x) => (Number.isFinite(x) ? x : null)),
    shape,
  );
}

/**
 * The map the run started from, on the version's grid: {values (flat), text}. In order: the
 * run's θ0 (a table, or a constant broadcast), the base map it started from, the estimator's
 * default θ0, else the first stored version (the closest record of the start there is).
 */
async function baseMap(v, doc) {
  const shape = doc.axes.map((a) => a.breakpoints.length);
  const unit = v.outputUnit || "-";
  const run = v.s.run;
  const theta0 = run.estimator_config?.theta0 ?? run.config?.theta0;
  const start = theta0 === undefined ? null : ops.baseOnGrid(theta0, shape);
  if (start) {
    const text =
      typeof theta0 === "number"
        ? `θ0 = ${fmt(theta0)} ${unit} in every cell (the run's constant start)`
        : run.base_map_id
          ? `base map #${run.base_map_id}, the run's starting map`
          : "the run's typed starting values";
    return { values: start, text };
  }
  if (run.base_map_id) {
    const map = await api.get(`/api/base-maps/${run.base_map_id}`).catch(() => null);
    const values = map ? ops.baseOnGrid(map.values, shape) : null;
    if (values) return { values, text: `base map #${map.id} “${map.name}”` };
  }
  const fallback = v.est?.defaults?.theta0;
  const values = fallback === undefined ? null : ops.baseOnGrid(fallback, shape);
  if (values) return { values, text: `θ0 = ${fmt(fallback)} ${unit}, the estimator's default` };
  const first = v.timeline.versions[0] ?? null;
  const firstDoc = first ? await v.timeline.doc(first) : doc;
  return {
    values: ops.flatten(firstDoc.values),
    text: `v${first?.number ?? 1}, the first stored version (the run's start was not stored)`,
  };
}
