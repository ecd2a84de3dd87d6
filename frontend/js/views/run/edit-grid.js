/**
 * The map editor's cell grid (views/run/edit.js): one slice of the table as an ARIA grid,
 * axis 0 down and axis 1 across (one row for a 1-D table), the value in each cell, selected,
 * locked and edited cells marked. Mouse: click, shift-click (rectangle), ctrl/⌘-click (add or
 * remove), drag (rectangle). Keyboard (roving tabindex): arrows move, shift+arrows extend,
 * space adds or removes, Enter selects one, Ctrl+A all, Escape none, L / R / S lock, reset,
 * smooth. The grid only reports what was asked; the controller owns the selection.
 */
import { fmt, h, withUnit } from "../../dom.js";
import { flatIndex, indexOf, rectangle } from "../../map-edit-ops.js";

const MOVES = { ArrowUp: [-1, 0], ArrowDown: [1, 0], ArrowLeft: [0, -1], ArrowRight: [0, 1] };
const KEY_TOOLS = { l: "lock", r: "reset", s: "smooth" };

/**
 * @param {HTMLElement} host
 * @param {{label: string, selection: () => Set<number>,
 *   pick: (k: number, how: {shift?: boolean, toggle?: boolean, from?: number}) => void,
 *   select: (cells: number[] | "all") => void, tool: (op: string) => void,
 *   focus: (k: number) => void}} on
 */
export function cellGrid(host, on) {
  let cells = new Map();
  let shape = [];
  let focus = 0;
  let drag = null;

  /** Draw the grid of the slice `tail` (indices of the axes beyond the second). */
  function render({ shape: dims, axes, tail = [] }) {
    shape = dims;
    const one = shape.length === 1;
    const rows = one ? 1 : shape[0];
    const cols = one ? shape[0] : shape[1];
    const at = (i, j) => flatIndex(one ? [j] : [i, j, ...tail], shape);
    const [a0, a1] = axes;
    cells = new Map();
    const corner = one ? "" : `${withUnit(a0.name, a0.unit)} ↓ / ${withUnit(a1.name, a1.unit)} →`;
    const table = h(
      "table",
      { role: "grid", "aria-multiselectable": "true", "aria-label": on.label },
      h(
        "thead",
        {},
        h(
          "tr",
          { role: "row" },
          h("th", { class: "rowh" }, corner),
          (one ? a0 : a1).breakpoints.map((b) =>
            h("th", { scope: "col", role: "columnheader" }, fmt(b)),
          ),
        ),
      ),
      h(
        "tbody",
        {},
        [...Array(rows).keys()].map((i) =>
          h(
            "tr",
            { role: "row" },
            h(
              "th",
              { class: "rowh", scope: "row", role: "rowheader" },
              one ? withUnit(a0.name, a0.unit) : fmt(a0.breakpoints[i]),
            ),
            [...Array(cols).keys()].map((j) => {
              const k = at(i, j);
              const td = h("td", { role: "gridcell", tabindex: "-1", dataset: { cell: k, i, j } });
              cells.set(k, td);
              return td;
            }),
          ),
        ),
      ),
    );
    table.addEventListener("mousedown", onMouseDown);
    table.addEventListener("mouseover", onMouseOver);
    table.addEventListener("keydown", onKey);
    table.addEventListener("focusin", (e) => {
      const k = cellOf(e.target);
      if (k !== null) on.focus(k);
    });
    host.replaceChildren(table);
    if (!cells.has(focus)) focus = at(0, 0);
  }

  /** Show the values, the selection, the locks and the edits of edit state `s`. */
  function paint(s, selected, focused) {
    if (cells.has(focused)) focus = focused;
    for (const [k, td] of cells) {
      const value = s.values[k];
      const locked = s.locked.has(k);
      const learned = s.learned[k];
      const edited = !(value === learned || (Number.isNaN(value) && Number.isNaN(learned)));
      td.textContent = fmt(value);
      td.classList.toggle("selected", selected.has(k));
      td.classList.toggle("locked", locked);
      td.classList.toggle("edited", edited);
      td.setAttribute("aria-selected", String(selected.has(k)));
      td.tabIndex = k === focus ? 0 : -1;
      td.title = [locked ? "locked" : "", edited ? `learned ${fmt(learned)}` : ""]
        .filter(Boolean)
        .join(" · ");
      if (locked) td.dataset.locked = "";
      else delete td.dataset.locked;
    }
  }

  function cellOf(target) {
    const td = target?.closest?.("td[data-cell]");
    return td ? Number(td.dataset.cell) : null;
  }

  function onMouseDown(e) {
    const k = cellOf(e.target);
    if (k === null || e.button !== 0) return;
    e.preventDefault(); // no text selection while dragging
    cells.get(k)?.focus();
    const toggle = e.ctrlKey || e.metaKey;
    if (e.shiftKey) {
      on.pick(k, { shift: true, toggle });
      return;
    }
    on.pick(k, { toggle });
    drag = { from: k, keep: toggle ? new Set(on.selection()) : new Set() };
    window.addEventListener("mouseup", () => (drag = null), { once: true });
  }

  function onMouseOver(e) {
    const k = drag ? cellOf(e.target) : null;
    if (k === null) return;
    on.select([...drag.keep, ...rectangle(indexOf(drag.from, shape), indexOf(k, shape), shape)]);
  }

  function onKey(e) {
    const k = cellOf(e.target);
    if (k === null) return;
    const td = cells.get(k);
    const key = e.key.length === 1 ? e.key.toLowerCase() : e.key;
    const mod = e.ctrlKey || e.metaKey;
    if (MOVES[key]) {
      e.preventDefault();
      const [di, dj] = MOVES[key];
      const i = Number(td.dataset.i) + di;
      const j = Number(td.dataset.j) + dj;
      const target = host.querySelector(`td[data-i="${i}"][data-j="${j}"]`);
      if (!target) return;
      const n = Number(target.dataset.cell);
      target.focus();
      if (e.shiftKey) on.pick(n, { shift: true, from: k });
      else on.focus(n);
    } else if (key === " " || key === "Enter") {
      e.preventDefault();
      on.pick(k, { toggle: key === " " || mod });
    } else if (key === "a" && mod) {
      e.preventDefault();
      on.select("all");
    } else if (key === "Escape") {
      on.select([]);
    } else if (KEY_TOOLS[key] && !mod && !e.altKey) {
      e.preventDefault();
      on.tool(KEY_TOOLS[key]);
    }
  }

  return {
    render,
    paint,
    /** Put the keyboard focus on the grid's current cell. */
    focus: () => cells.get(focus)?.focus(),
  };
}
