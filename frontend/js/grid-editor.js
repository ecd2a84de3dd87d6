/**
 * Table grid editor for the run form: breakpoints per axis (one to three axes, typed or fitted
 * to the data), a coverage plot of the operating points over the grid, and the starting map —
 * constant θ0, values typed per cell (with locked cells; a 3-D table one slice at a time), or
 * an imported base map, which is sent only when one is chosen and the grid still matches it.
 */
import { api, showError } from "./api.js";
import { SELECT } from "./constants.js";
import {
  fmt,
  h,
  icon,
  ICONS,
  niceBreakpoints,
  parseNumberList,
  quantile,
  withUnit,
} from "./dom.js";
import { axis, baseLayout, purge, react, SCALE_VIRIDIS, STATIC_CONFIG, theme } from "./plot.js";

/** The estimators' tables go up to three dimensions (the API itself takes any number of axes). */
export const MAX_AXES = 3;
const DEFAULT_BREAKPOINTS = 8;
const MAX_BREAKPOINTS = 64;
/** The field an error about the starting map is shown next to (the base-map picker). */
const BASE_FIELD = "base_map_id";

/**
 * @param {{channels: {name, unit}[], preview: object|null, axes?: string[], baseMaps?: object[],
 *   saved?: object|null, onChange?: () => void}} opts
 *   saved: a snapshot() to start from (the draft of a reloaded form); onChange: any edit
 */
export function gridEditor({
  channels,
  preview,
  axes: initial = [],
  baseMaps = [],
  saved = null,
  onChange = () => {},
}) {
  const state = {
    axes: [],
    start: "constant",
    values: null,
    locked: new Set(),
    lockMode: false,
    baseMap: null,
    baseMaps: [...baseMaps],
    slice: 0,
  };
  const axesHost = h("div", { "data-axes": "" });
  const coverage = h("div", {
    class: "plot short",
    role: "img",
    "aria-label": "Operating points over the grid",
  });
  const startHost = h("div", { "data-start-map": "" });
  const addButton = h(
    "button",
    {
      type: "button",
      class: "small",
      "data-add-axis": "",
      onclick: () => {
        addAxis();
        changed();
      },
    },
    icon(ICONS.plus),
    "Add axis",
  );
  const el = h(
    "div",
    { class: "grid-editor" },
    axesHost,
    h(
      "div",
      { class: "row", style: { margin: "8px 0 14px" } },
      addButton,
      h(
        "span",
        { class: "help" },
        `Up to ${MAX_AXES} axes. Breakpoints are in the column's unit, strictly increasing.`,
      ),
    ),
    h("div", { class: "label" }, "Coverage of the log over the grid"),
    coverage,
    h("div", { class: "label", style: { marginTop: "14px" } }, "Starting map"),
    startHost,
  );

  const channelInfo = (name) => channels.find((c) => c.name === name) ?? { name, unit: "" };
  const column = (name) => preview?.channels?.[name]?.values ?? [];
  const changed = () => onChange();

  function fitted(name, n) {
    const vals = column(name).filter((v) => v !== null);
    if (!vals.length) return [];
    return niceBreakpoints(quantile(vals, 0.005), quantile(vals, 0.995), n);
  }

  function addAxis(name) {
    if (state.axes.length >= MAX_AXES) return;
    const used = new Set(state.axes.map((a) => a.name));
    const pick = name ?? channels.find((c) => !used.has(c.name))?.name ?? channels[0]?.name;
    const n = DEFAULT_BREAKPOINTS;
    state.axes.push({
      name: pick,
      unit: channelInfo(pick).unit ?? "",
      text: fitted(pick, n).join(", "),
      n,
    });
    renderAxes();
  }

  function renderAxes() {
    axesHost.replaceChildren(
      ...state.axes.map((ax, k) => {
        const pre = `table.axes.${k}`;
        const sel = h(
          "select",
          { id: `axis-${k}-name`, "data-field": `${pre}.name`, name: `${pre}.name` },
          channels.map((c) =>
            h("option", { value: c.name, selected: c.name === ax.name }, withUnit(c.name, c.unit)),
          ),
        );
        const unit = h("input", {
          type: "text",
          id: `axis-${k}-unit`,
          "data-field": `${pre}.unit`,
          value: ax.unit,
        });
        const bps = h("input", {
          type: "text",
          id: `axis-${k}-bp`,
          class: "mono",
          "data-field": `${pre}.breakpoints`,
          name: `${pre}.breakpoints`,
          value: ax.text,
          autocomplete: "off",
        });
        const count = h("input", {
          type: "number",
          id: `axis-${k}-n`,
          min: "2",
          max: String(MAX_BREAKPOINTS),
          step: "1",
          value: String(ax.n),
          style: { width: "70px" },
          "aria-label": `Number of breakpoints of axis ${k + 1}`,
        });
        sel.addEventListener("change", () => {
          ax.name = sel.value;
          ax.unit = channelInfo(sel.value).unit ?? "";
          ax.text = fitted(sel.value, ax.n).join(", ");
          renderAxes();
          changed();
        });
        unit.addEventListener("input", () => {
          ax.unit = unit.value;
        });
        bps.addEventListener("change", () => {
          ax.text = bps.value;
          ax.n = safeList(bps.value).length || ax.n;
          count.value = String(ax.n);
          refreshGrid();
          changed();
        });
        const fit = () => {
          ax.n = Math.max(2, Math.min(MAX_BREAKPOINTS, Number(count.value) || DEFAULT_BREAKPOINTS));
          ax.text = fitted(ax.name, ax.n).join(", ");
          bps.value = ax.text;
          refreshGrid();
          changed();
        };
        count.addEventListener("change", fit);
        return h(
          "div",
          { class: "axis-row", "data-axis": k },
          h(
            "div",
            { class: "field" },
            h("label", { for: `axis-${k}-name` }, `Axis ${k + 1} column`),
            sel,
          ),
          h("div", { class: "field" }, h("label", { for: `axis-${k}-unit` }, "Unit"), unit),
          h(
            "div",
            { class: "field" },
            h("label", { for: `axis-${k}-bp` }, "Breakpoints"),
            bps,
            h(
              "div",
              { class: "row", style: { marginTop: "6px" } },
              h("label", { for: `axis-${k}-n`, style: { margin: 0, fontWeight: 500 } }, "Count"),
              count,
              h(
                "button",
                { type: "button", class: "small", onclick: fit, "data-fit": k },
                "Fit to data",
              ),
            ),
          ),
          h(
            "div",
            { class: "field" },
            h("div", { class: "label" }, "\u00a0"),
            h(
              "button",
              {
                type: "button",
                class: "small ghost icon",
                "aria-label": `Remove axis ${k + 1}`,
                disabled: state.axes.length <= 1,
                onclick: () => {
                  state.axes.splice(k, 1);
                  renderAxes();
                  changed();
                },
              },
              icon(ICONS.x),
            ),
          ),
        );
      }),
    );
    addButton.disabled = state.axes.length >= MAX_AXES;
    refreshGrid();
  }

  function refreshGrid() {
    drawCoverage();
    if (state.start === "values") renderValues();
  }

  function drawCoverage() {
    const t = theme();
    const bp = state.axes.map((a) => safeList(a.text));
    if (!state.axes.length) return purge(coverage);
    const x = column(state.axes[0].name);
    const shapes = [];
    const line = { color: t.accent, width: 1, dash: "dot" };
    for (const v of bp[0])
      shapes.push({ type: "line", x0: v, x1: v, yref: "paper", y0: 0, y1: 1, line });
    if (state.axes.length === 1) {
      react(
        coverage,
        [{ type: "histogram", x, marker: { color: t.text3 }, opacity: 0.6, hoverinfo: "skip" }],
        baseLayout({
          shapes,
          xaxis: axis(withUnit(state.axes[0].name, state.axes[0].unit)),
          yaxis: axis("samples"),
          bargap: 0.05,
          margin: { l: 50, r: 10, t: 6, b: 40 },
        }),
        STATIC_CONFIG,
      );
      return;
    }
    const y = column(state.axes[1].name);
    for (const v of bp[1])
      shapes.push({ type: "line", y0: v, y1: v, xref: "paper", x0: 0, x1: 1, line });
    // A third axis colours the points (its breakpoints are listed on the colour bar).
    const third = state.axes[2];
    const marker = third
      ? {
          size: 4,
          opacity: 0.7,
          color: column(third.name),
          colorscale: SCALE_VIRIDIS,
          showscale: true,
          colorbar: {
            thickness: 10,
            outlinewidth: 0,
            title: {
              text: withUnit(third.name, third.unit),
              side: "right",
              font: { size: 11, color: t.text2 },
            },
            tickfont: { size: 10, color: t.text3 },
            tickvals: bp[2],
            tickmode: "array",
          },
        }
      : { size: 4, color: t.text3, opacity: 0.55 };
    react(
      coverage,
      [{ type: "scatter", mode: "markers", x, y, hoverinfo: "skip", marker }],
      baseLayout({
        shapes,
        xaxis: axis(withUnit(state.axes[0].name, state.axes[0].unit)),
        yaxis: axis(withUnit(state.axes[1].name, state.axes[1].unit)),
        margin: { l: 56, r: 10, t: 6, b: 40 },
      }),
      STATIC_CONFIG,
    );
  }

  /* ---------- starting map ---------- */
  const fill = h("input", {
    type: "number",
    id: "grid-fill",
    step: "any",
    value: "0",
    style: { width: "110px" },
  });
  const valuesHost = h("div", { "data-values-grid": "" });
  const lockToggle = h("input", { type: "checkbox", id: "grid-lock" });
  const lockCount = h("div", { class: "help", "aria-live": "polite" });
  const baseSelect = h("select", { id: "base-map", name: BASE_FIELD, "data-field": BASE_FIELD });
  const baseFile = h("input", {
    type: "file",
    id: "base-map-file",
    accept: ".json,.csv,.dcm",
    name: "file",
  });
  const baseInfo = h("div", { class: "help", "data-base-info": "" });
  const startPanel = h("div", {});

  const radios = [
    ["constant", "Constant θ0 (from the configuration)"],
    ["values", "Type the cell values"],
    ["base", "Import a base map"],
  ].map(([value, label]) =>
    h(
      "label",
      { class: "check", for: `start-${value}` },
      h("input", {
        type: "radio",
        name: "start",
        id: `start-${value}`,
        value,
        checked: value === state.start,
        onchange: () => {
          state.start = value;
          renderStart();
          changed();
        },
      }),
      label,
    ),
  );
  startHost.append(
    h(
      "div",
      {
        class: "row",
        role: "radiogroup",
        "aria-label": "Starting map",
        style: { gap: "18px", marginBottom: "10px" },
      },
      radios,
    ),
    startPanel,
  );

  function renderStart() {
    for (const r of radios) {
      const input = r.firstChild;
      input.checked = input.value === state.start;
    }
    if (state.start === "constant") {
      startPanel.replaceChildren(
        h("p", { class: "help" }, "Every cell starts at the estimator's θ0 with variance P0."),
      );
    } else if (state.start === "values") {
      startPanel.replaceChildren(
        h(
          "div",
          { class: "row", style: { marginBottom: "8px" } },
          h("label", { for: "grid-fill", style: { margin: 0 } }, "Fill"),
          fill,
          h(
            "button",
            {
              type: "button",
              class: "small",
              onclick: () => {
                state.values = null;
                renderValues();
                changed();
              },
            },
            "Fill all",
          ),
          h("span", { class: "spacer" }),
          h(
            "label",
            { class: "check", for: "grid-lock" },
            lockToggle,
            "Lock mode (click a cell to lock it)",
          ),
        ),
        valuesHost,
      );
      renderValues();
    } else {
      renderBaseOptions();
      startPanel.replaceChildren(
        h(
          "div",
          { class: "fields two" },
          h("div", { class: "field" }, h("label", { for: "base-map" }, "Base map"), baseSelect),
          h(
            "div",
            { class: "field" },
            h("label", { for: "base-map-file" }, "…or upload a map (JSON, CSV, DCM)"),
            baseFile,
          ),
        ),
        baseInfo,
      );
      describeBase();
    }
  }

  lockToggle.addEventListener("change", () => {
    state.lockMode = lockToggle.checked;
  });

  function shape() {
    return state.axes.map((a) => safeList(a.text).length);
  }

  /** The typed values as a table of axis 0 × axis 1; a third axis is edited one slice at a time. */
  function renderValues() {
    const dims = shape();
    const bps = state.axes.map((a) => safeList(a.text));
    const f = Number(fill.value) || 0;
    if (!state.values || !sameShape(state.values, dims)) state.values = blank(dims, f);
    if (dims.some((n) => n === 0)) {
      valuesHost.replaceChildren(h("p", { class: "help" }, "Fix the breakpoints first."));
      return;
    }
    const three = dims.length === 3;
    state.slice = Math.min(state.slice, three ? dims[2] - 1 : 0);
    const k = state.slice;
    const flatOf = (i, j) =>
      dims.length === 1 ? j : three ? (i * dims[1] + j) * dims[2] + k : i * dims[1] + j;
    const get = (i, j) =>
      dims.length === 1 ? state.values[j] : three ? state.values[i][j][k] : state.values[i][j];
    const set = (i, j, v) => {
      if (dims.length === 1) state.values[j] = v;
      else if (three) state.values[i][j][k] = v;
      else state.values[i][j] = v;
    };
    const rows = dims.length === 1 ? [0] : [...Array(dims[0]).keys()];
    const cols = dims.length === 1 ? dims[0] : dims[1];
    const where = (i, j) =>
      dims.length === 1
        ? `${state.axes[0].name} = ${bps[0][j]}`
        : `${state.axes[0].name} = ${bps[0][i]}, ${state.axes[1].name} = ${bps[1][j]}` +
          (three ? `, ${state.axes[2].name} = ${bps[2][k]}` : "");
    const table = h(
      "table",
      {},
      h(
        "thead",
        {},
        h(
          "tr",
          {},
          h(
            "th",
            { class: "rowh" },
            dims.length === 1 ? "" : `${state.axes[0].name} ↓ / ${state.axes[1].name} →`,
          ),
          (dims.length === 1 ? bps[0] : bps[1]).map((v) => h("th", { scope: "col" }, fmt(v))),
        ),
      ),
      h(
        "tbody",
        {},
        rows.map((i) =>
          h(
            "tr",
            {},
            h(
              "th",
              { class: "rowh", scope: "row" },
              dims.length === 1 ? state.axes[0].name : fmt(bps[0][i]),
            ),
            [...Array(cols).keys()].map((j) => {
              const flatIndex = flatOf(i, j);
              const input = h("input", {
                type: "number",
                step: "any",
                value: String(get(i, j)),
                "aria-label": `Cell ${where(i, j)}`,
                class: state.locked.has(flatIndex) ? "locked" : null,
                dataset: { cell: flatIndex },
              });
              input.addEventListener("change", () => {
                set(i, j, Number(input.value));
                changed();
              });
              const toggleLock = () => {
                if (state.locked.has(flatIndex)) state.locked.delete(flatIndex);
                else state.locked.add(flatIndex);
                input.classList.toggle("locked", state.locked.has(flatIndex));
                input.title = state.locked.has(flatIndex) ? "locked" : "";
                lockCount.textContent = lockText();
                changed();
              };
              input.addEventListener("click", () => state.lockMode && toggleLock());
              input.addEventListener("keydown", (e) => {
                if (state.lockMode && (e.key === "l" || e.key === "L")) {
                  e.preventDefault();
                  toggleLock();
                }
              });
              return h("td", {}, input);
            }),
          ),
        ),
      ),
    );
    let picker = null;
    if (three) {
      const a2 = state.axes[2];
      const select = h(
        "select",
        { id: "grid-slice", "data-grid-slice": "" },
        bps[2].map((v, n) =>
          h(
            "option",
            { value: String(n), selected: n === k },
            `${fmt(v)}${a2.unit ? ` ${a2.unit}` : ""}`,
          ),
        ),
      );
      select.addEventListener("change", () => {
        state.slice = Number(select.value);
        renderValues();
        valuesHost.querySelector(SELECT.id(select.id))?.focus();
      });
      picker = h(
        "div",
        { class: "field slice-picker" },
        h("label", { for: "grid-slice" }, `Slice at ${a2.name}`),
        select,
      );
    }
    valuesHost.replaceChildren(
      ...[picker, h("div", { class: "values-grid" }, table), lockCount].filter(Boolean),
    );
    lockCount.textContent = lockText();
  }

  function lockText() {
    return `${state.locked.size} locked cell(s) — locked cells keep their value and variance.`;
  }

  function renderBaseOptions() {
    const id = state.baseMap?.id ?? null;
    baseSelect.replaceChildren(
      h("option", { value: "" }, state.baseMaps.length ? "— choose —" : "no base maps yet"),
      ...state.baseMaps.map((m) =>
        h("option", { value: String(m.id), selected: m.id === id }, `#${m.id} ${m.name}`),
      ),
    );
  }

  function describeBase() {
    const map = state.baseMap;
    if (!map) {
      baseInfo.textContent = "";
      return;
    }
    const lin = map.lineage;
    baseInfo.textContent =
      `${map.axes?.map((a) => `${a.name} (${a.breakpoints.length})`).join(" × ") ?? ""}` +
      (lin?.run_id
        ? ` · from run #${lin.run_id}, ${lin.version_number ? `v${lin.version_number}` : `version id ${lin.version_id}`} (${lin.estimator})`
        : "");
  }

  /** Take a base map's grid (axes and breakpoints) unless keepAxes (a restored draft). */
  function applyBaseMap(map, { keepAxes = false } = {}) {
    state.baseMap = map ?? null;
    if (map?.axes?.length && !keepAxes) {
      state.axes = map.axes.map((a) => ({
        name: a.name,
        unit: a.unit ?? "",
        text: a.breakpoints.join(", "),
        n: a.breakpoints.length,
      }));
      renderAxes();
    }
    describeBase();
  }

  baseSelect.addEventListener("change", async () => {
    const id = Number(baseSelect.value);
    if (!id) {
      applyBaseMap(null);
      changed();
      return;
    }
    try {
      applyBaseMap(await api.get(`/api/base-maps/${id}`));
      changed();
    } catch (err) {
      showError(el, Object.assign(err, { field: BASE_FIELD }));
    }
  });

  baseFile.addEventListener("change", async () => {
    const f = baseFile.files[0];
    if (!f) return;
    const body = new FormData();
    body.append("file", f, f.name);
    body.append("name", f.name.replace(/\.[^.]+$/, ""));
    try {
      const map = await api.upload("/api/base-maps", body);
      state.baseMaps.unshift(map);
      state.baseMap = map;
      renderBaseOptions();
      applyBaseMap(map);
      changed();
    } catch (err) {
      showError(el, Object.assign(err, { field: BASE_FIELD }));
    }
  });

  /* ---------- start ---------- */
  const names = new Set(channels.map((c) => c.name));
  const savedAxes = (saved?.axes ?? []).filter((a) => names.has(a?.name)).slice(0, MAX_AXES);
  if (savedAxes.length) {
    state.axes = savedAxes.map((a) => ({
      name: a.name,
      unit: String(a.unit ?? ""),
      text: String(a.text ?? ""),
      n: Number(a.n) || DEFAULT_BREAKPOINTS,
    }));
    state.start = ["constant", "values", "base"].includes(saved.start) ? saved.start : "constant";
    state.values = saved.values ?? null;
    state.locked = new Set((saved.locked ?? []).filter(Number.isInteger));
    state.slice = Number(saved.slice) || 0;
    renderAxes();
    if (saved.baseMapId) {
      const known = state.baseMaps.find((m) => m.id === saved.baseMapId);
      if (known) applyBaseMap(known, { keepAxes: true });
    }
  } else {
    for (const name of initial) addAxis(name);
    if (!state.axes.length && channels.length) {
      addAxis(channels[0].name);
      if (channels.length > 2) addAxis(channels[1].name);
    }
  }
  renderStart();

  return {
    el,
    /** Point the axes at these columns (e.g. after the dataset or mapping changed). */
    setAxes(list) {
      state.axes = [];
      for (const n of list.slice(0, MAX_AXES)) addAxis(n);
    },
    redraw: drawCoverage,
    destroy: () => purge(coverage),
    /** What a reload needs to show the same editor (JSON-serialisable). */
    snapshot() {
      return {
        axes: state.axes.map((a) => ({ ...a })),
        start: state.start,
        values: state.start === "values" ? state.values : null,
        locked: [...state.locked],
        slice: state.slice,
        baseMapId: state.baseMap?.id ?? null,
      };
    },
    /**
     * {table, base_map_id, locked}; throws an Error with .field (shown next to that control)
     * for unreadable breakpoints, a missing base map, or a grid that no longer matches it.
     */
    read() {
      const axes = state.axes.map((a, k) => {
        let breakpoints;
        try {
          breakpoints = parseNumberList(a.text);
        } catch (err) {
          throw Object.assign(new Error(err.message), { field: `table.axes.${k}.breakpoints` });
        }
        if (breakpoints.length < 2) {
          throw Object.assign(new Error("at least two breakpoints are needed"), {
            field: `table.axes.${k}.breakpoints`,
          });
        }
        const bad = breakpoints.findIndex((v, i) => i > 0 && !(v > breakpoints[i - 1]));
        if (bad > 0) {
          throw Object.assign(
            new Error(
              `breakpoints must be strictly increasing: ${breakpoints[bad]} follows ${breakpoints[bad - 1]}`,
            ),
            { field: `table.axes.${k}.breakpoints` },
          );
        }
        return { name: a.name, breakpoints, unit: a.unit || undefined };
      });
      const table = { axes };
      let baseMapId = null;
      if (state.start === "values") {
        const dims = axes.map((a) => a.breakpoints.length);
        if (!state.values || !sameShape(state.values, dims))
          state.values = blank(dims, Number(fill.value) || 0);
        table.values = state.values;
      } else if (state.start === "base") {
        const map = state.baseMap;
        if (!map) {
          throw Object.assign(
            new Error("Choose a base map (or upload one), or pick another starting map."),
            { field: BASE_FIELD },
          );
        }
        const mismatch = gridMismatch(map.axes ?? [], axes);
        if (mismatch) {
          throw Object.assign(
            new Error(
              `The grid no longer matches base map #${map.id}: ${mismatch}. ` +
                "Choose the map again to take its grid, or start from another map.",
            ),
            { field: BASE_FIELD },
          );
        }
        table.values = map.values;
        baseMapId = map.id;
      }
      return {
        table,
        base_map_id: baseMapId,
        locked:
          state.start === "values" && state.locked.size
            ? [...state.locked].sort((a, b) => a - b)
            : null,
      };
    },
  };
}

/** Why a base map's axes differ from the form's (null when they match), in words. */
function gridMismatch(mapAxes, axes) {
  if (mapAxes.length !== axes.length)
    return `it has ${mapAxes.length} axes, the form ${axes.length}`;
  for (let k = 0; k < axes.length; k += 1) {
    const a = mapAxes[k].breakpoints;
    const b = axes[k].breakpoints;
    const same =
      a.length === b.length &&
      a.every((v, i) => Math.abs(v - b[i]) <= 1e-9 * Math.max(1, Math.abs(v)));
    if (!same) return `axis ${k + 1} (${axes[k].name}) has other breakpoints`;
  }
  return null;
}

function safeList(text) {
  try {
    return parseNumberList(text);
  } catch {
    return [];
  }
}

/** A table of the given shape filled with f (nested lists in axis order). */
function blank(dims, f) {
  if (dims.length === 1) return Array(dims[0]).fill(f);
  return Array.from({ length: dims[0] }, () => blank(dims.slice(1), f));
}

function sameShape(values, dims) {
  if (!Array.isArray(values) || values.length !== dims[0]) return false;
  if (dims.length === 1) return values.every((v) => !Array.isArray(v));
  return values.every((v) => sameShape(v, dims.slice(1)));
}
