/**
 * The map browser of one ECU: a search box (name and description, case-insensitive), a filter
 * per characteristic type and the matching characteristics a page at a time
 * (GET /api/ecus/{id}/maps?q=&type=&limit=&offset=, docs/calibration.md#dashboard).
 */
import { api } from "../../api.js";
import { debounce, fmtInt, h } from "../../dom.js";

/** The characteristic types one can filter on; the first three are shown at first. */
export const TYPES = Object.freeze(["MAP", "CURVE", "VAL_BLK", "VALUE"]);
export const DEFAULT_TYPES = Object.freeze(["MAP", "CURVE", "VAL_BLK"]);
const PAGE = 50;
const SEARCH_DELAY_MS = 200;
const CURRENT = '[aria-current="true"]';
const ITEM = "[data-map]";

/** "4 × 5" for a MAP, "8" for a CURVE, "scalar" for a VALUE. */
export function shapeText(shape) {
  return shape?.length ? shape.join(" × ") : "scalar";
}

/**
 * @param {{ecuId: number, q: string, types: string[], selected: string|null, signal: AbortSignal,
 *   onSelect: (name: string) => void, onQuery: (q: string, types: string[]) => void}} opts
 */
export function mapBrowser({ ecuId, q, types, selected, signal, onSelect, onQuery }) {
  const state = { q, types: new Set(types), selected, items: [], total: 0, seq: 0 };
  const search = h("input", {
    type: "search",
    id: "ecu-search",
    value: q,
    placeholder: "Search names and descriptions",
    autocomplete: "off",
    "aria-controls": "ecu-map-list",
  });
  const typeButtons = TYPES.map((t) =>
    h(
      "button",
      {
        type: "button",
        "data-type": t,
        "aria-pressed": String(state.types.has(t)),
        onclick: (e) => {
          if (state.types.has(t)) state.types.delete(t);
          else state.types.add(t);
          e.currentTarget.setAttribute("aria-pressed", String(state.types.has(t)));
          changed();
        },
      },
      t,
    ),
  );
  const count = h("div", { class: "help", "aria-live": "polite", "data-map-count": "" });
  const list = h("ul", { class: "map-list", id: "ecu-map-list", "data-map-list": "" });
  const more = h(
    "button",
    { type: "button", class: "small", hidden: true, onclick: () => load(true) },
    "Show more",
  );
  const el = h(
    "div",
    { class: "map-browser" },
    h(
      "div",
      { class: "field" },
      h("label", { for: "ecu-search" }, "Search characteristics"),
      search,
    ),
    h("div", { class: "seg", role: "group", "aria-label": "Characteristic types" }, typeButtons),
    count,
    list,
    h("div", { class: "row", style: { justifyContent: "center" } }, more),
  );

  const changed = () => {
    onQuery(state.q, [...state.types]);
    load(false);
  };
  search.addEventListener(
    "input",
    debounce(() => {
      state.q = search.value.trim();
      changed();
    }, SEARCH_DELAY_MS),
  );

  /** Fetch the first page (or the next one, appended); answers to older queries are dropped. */
  async function load(append) {
    const seq = ++state.seq;
    const offset = append ? state.items.length : 0;
    let page;
    try {
      page = await api.get(`/api/ecus/${ecuId}/maps`, {
        query: { q: state.q, type: [...state.types].join(","), limit: PAGE, offset },
        signal,
      });
    } catch (err) {
      if (err.name === "AbortError" || seq !== state.seq) return;
      list.replaceChildren(h("li", { class: "banner error", role: "alert" }, err.message));
      return;
    }
    if (seq !== state.seq) return;
    state.items = append ? [...state.items, ...page.items] : page.items;
    state.total = page.total;
    render();
    if (!append) revealSelected();
  }

  /** Scroll the list (not the page) to the open characteristic. */
  function revealSelected() {
    const item = list.querySelector(CURRENT)?.parentElement;
    if (item) list.scrollTop = Math.max(0, item.offsetTop - list.clientHeight / 3);
  }

  function render() {
    count.textContent = `${fmtInt(state.items.length)} of ${fmtInt(state.total)} characteristics`;
    more.hidden = state.items.length >= state.total;
    if (!state.items.length) {
      list.replaceChildren(h("li", { class: "empty" }, "Nothing matches."));
      return;
    }
    list.replaceChildren(...state.items.map(item));
  }

  function item(c) {
    return h(
      "li",
      {},
      h(
        "button",
        {
          type: "button",
          class: "map-item",
          "aria-current": c.name === state.selected ? "true" : null,
          dataset: { map: c.name },
          onclick: () => select(c.name),
        },
        h(
          "span",
          { class: "map-item-head" },
          h("span", { class: "map-name" }, c.name),
          h("span", { class: "tag" }, c.type),
        ),
        h(
          "span",
          { class: "map-item-sub" },
          `${shapeText(c.shape)}${c.unit ? ` · ${c.unit}` : ""}${c.description ? ` · ${c.description}` : ""}`,
        ),
      ),
    );
  }

  function select(name) {
    state.selected = name;
    for (const b of list.querySelectorAll(ITEM)) {
      if (b.dataset.map === name) b.setAttribute("aria-current", "true");
      else b.removeAttribute("aria-current");
    }
    onSelect(name);
  }

  load(false);
  return { el };
}
