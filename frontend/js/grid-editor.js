/**
 * Table grid editor for the run form: breakpoints per axis (typed, or fitted to the data),
 * a coverage plot of the operating points over the grid, and the starting map — constant θ0,
 * values typed per cell (with locked cells), or an imported base map.
 */
import { api, showError } from "./api.js";
import { fmt, h, icon, ICONS, niceBreakpoints, parseNumberList, quantile, withUnit } from "./dom.js";
import { axis, baseLayout, purge, react, STATIC_CONFIG, theme } from "./plot.js";

const MAX_AXES = 2;

/**
 * @param {{channels: {name, unit}[], preview: object|null, axes?: string[], baseMaps?: object[]}} opts
 */
export function gridEditor({ channels, preview, axes: initial = [], baseMaps = [] }) {
  const state = {
    axes: [],
    start: "constant",
    values: null,
    locked: new Set(),
    lockMode: false,
    baseMapId: null,
    baseMaps: [...baseMaps],
  };
  const axesHost = h("div", { "data-axes": "" });
  const coverage = h("div", { class: "plot short", role: "img", "aria-label": "Operating points over the grid" });
  const startHost = h("div", { "data-start-map": "" });
  const el = h("div", { class: "grid-editor" },
    axesHost,
    h("div", { class: "row", style: { margin: "8px 0 14px" } },
      h("button", { type: "button", class: "small", "data-add-axis": "", onclick: () => addAxis() }, icon(ICONS.plus), "Add axis"),
      h("span", { class: "help" }, "Breakpoints are in the column's unit, strictly increasing.")),
    h("div", { class: "label" }, "Coverage of the log over the grid"),
    coverage,
    h("div", { class: "label", style: { marginTop: "14px" } }, "Starting map"),
    startHost);

  const channelInfo = (name) => channels.find((c) => c.name === name) ?? { name, unit: "" };
  const column = (name) => preview?.channels?.[name]?.values ?? [];

  function fitted(name, n) {
    const vals = column(name).filter((v) => v !== null);
    if (!vals.length) return [];
    return niceBreakpoints(quantile(vals, 0.005), quantile(vals, 0.995), n);
  }

  function addAxis(name) {
    if (state.axes.length >= MAX_AXES) return;
    const used = new Set(state.axes.map((a) => a.name));
    const pick = name ?? channels.find((c) => !used.has(c.name))?.name ?? channels[0]?.name;
    const n = state.axes.length === 0 ? 8 : 8;
    state.axes.push({ name: pick, unit: channelInfo(pick).unit ?? "", text: fitted(pick, n).join(", "), n });
    renderAxes();
  }

  function renderAxes() {
    axesHost.replaceChildren(...state.axes.map((ax, k) => {
      const pre = `table.axes.${k}`;
      const sel = h("select", { id: `axis-${k}-name`, "data-field": `${pre}.name`, name: `${pre}.name` },
        channels.map((c) => h("option", { value: c.name, selected: c.name === ax.name }, withUnit(c.name, c.unit))));
      const unit = h("input", { type: "text", id: `axis-${k}-unit`, "data-field": `${pre}.unit`, value: ax.unit });
      const bps = h("input", { type: "text", id: `axis-${k}-bp`, class: "mono", "data-field": `${pre}.breakpoints`,
        name: `${pre}.breakpoints`, value: ax.text, autocomplete: "off" });
      const count = h("input", { type: "number", id: `axis-${k}-n`, min: "2", max: "64", step: "1", value: String(ax.n),
        style: { width: "70px" }, "aria-label": `Number of breakpoints of axis ${k + 1}` });
      sel.addEventListener("change", () => {
        ax.name = sel.value;
        ax.unit = channelInfo(sel.value).unit ?? "";
        ax.text = fitted(sel.value, ax.n).join(", ");
        renderAxes();
      });
      unit.addEventListener("input", () => { ax.unit = unit.value; });
      bps.addEventListener("change", () => {
        ax.text = bps.value;
        ax.n = safeList(bps.value).length || ax.n;
        count.value = String(ax.n);
        refreshGrid();
      });
      const fit = () => {
        ax.n = Math.max(2, Math.min(64, Number(count.value) || 8));
        ax.text = fitted(ax.name, ax.n).join(", ");
        bps.value = ax.text;
        refreshGrid();
      };
      count.addEventListener("change", fit);
      return h("div", { class: "axis-row", "data-axis": k },
        h("div", { class: "field" }, h("label", { for: `axis-${k}-name` }, `Axis ${k + 1} column`), sel),
        h("div", { class: "field" }, h("label", { for: `axis-${k}-unit` }, "Unit"), unit),
        h("div", { class: "field" }, h("label", { for: `axis-${k}-bp` }, "Breakpoints"), bps,
          h("div", { class: "row", style: { marginTop: "6px" } },
            h("label", { for: `axis-${k}-n`, style: { margin: 0, fontWeight: 500 } }, "Count"), count,
            h("button", { type: "button", class: "small", onclick: fit, "data-fit": k }, "Fit to data"))),
        h("div", { class: "field" }, h("div", { class: "label" }, "\u00a0"),
          h("button", { type: "button", class: "small ghost icon", "aria-label": `Remove axis ${k + 1}`,
            disabled: state.axes.length <= 1, onclick: () => { state.axes.splice(k, 1); renderAxes(); } }, icon(ICONS.x))));
    }));
    el.querySelector("[data-add-axis]").disabled = state.axes.length >= MAX_AXES;
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
    for (const v of bp[0]) shapes.push({ type: "line", x0: v, x1: v, yref: "paper", y0: 0, y1: 1, line });
    if (state.axes.length === 1) {
      react(coverage, [{ type: "histogram", x, marker: { color: t.text3 }, opacity: 0.6, hoverinfo: "skip" }],
        baseLayout({ shapes, xaxis: axis(withUnit(state.axes[0].name, state.axes[0].unit)), yaxis: axis("samples"),
          bargap: 0.05, margin: { l: 50, r: 10, t: 6, b: 40 } }), STATIC_CONFIG);
      return;
    }
    const y = column(state.axes[1].name);
    for (const v of bp[1]) shapes.push({ type: "line", y0: v, y1: v, xref: "paper", x0: 0, x1: 1, line });
    react(coverage, [{ type: "scatter", mode: "markers", x, y, hoverinfo: "skip",
      marker: { size: 4, color: t.text3, opacity: 0.55 } }],
    baseLayout({ shapes, xaxis: axis(withUnit(state.axes[0].name, state.axes[0].unit)),
      yaxis: axis(withUnit(state.axes[1].name, state.axes[1].unit)), margin: { l: 56, r: 10, t: 6, b: 40 } }), STATIC_CONFIG);
  }

  /* ---------- starting map ---------- */
  const fill = h("input", { type: "number", id: "grid-fill", step: "any", value: "0", style: { width: "110px" } });
  const valuesHost = h("div", { "data-values-grid": "" });
  const lockToggle = h("input", { type: "checkbox", id: "grid-lock" });
  const lockCount = h("div", { class: "help", "aria-live": "polite" });
  const baseSelect = h("select", { id: "base-map", name: "base_map_id", "data-field": "base_map_id" });
  const baseFile = h("input", { type: "file", id: "base-map-file", accept: ".json,.csv,.dcm", name: "file" });
  const startPanel = h("div", {});

  const radios = [
    ["constant", "Constant θ0 (from the configuration)"],
    ["values", "Type the cell values"],
    ["base", "Import a base map"],
  ].map(([value, label]) =>
    h("label", { class: "check", for: `start-${value}` },
      h("input", { type: "radio", name: "start", id: `start-${value}`, value, checked: value === state.start,
        onchange: () => { state.start = value; renderStart(); } }), label));
  startHost.append(h("div", { class: "row", role: "radiogroup", "aria-label": "Starting map", style: { gap: "18px", marginBottom: "10px" } }, radios), startPanel);

  function renderStart() {
    if (state.start === "constant") {
      startPanel.replaceChildren(h("p", { class: "help" }, "Every cell starts at the estimator's θ0 with variance P0."));
    } else if (state.start === "values") {
      startPanel.replaceChildren(
        h("div", { class: "row", style: { marginBottom: "8px" } },
          h("label", { for: "grid-fill", style: { margin: 0 } }, "Fill"), fill,
          h("button", { type: "button", class: "small", onclick: () => { state.values = null; renderValues(); } }, "Fill all"),
          h("span", { class: "spacer" }),
          h("label", { class: "check", for: "grid-lock" }, lockToggle, "Lock mode (click a cell to lock it)")),
        valuesHost);
      renderValues();
    } else {
      renderBaseOptions();
      startPanel.replaceChildren(
        h("div", { class: "fields two" },
          h("div", { class: "field" }, h("label", { for: "base-map" }, "Base map"), baseSelect),
          h("div", { class: "field" }, h("label", { for: "base-map-file" }, "…or upload a map (JSON, CSV, DCM)"), baseFile)),
        h("div", { class: "help", "data-base-info": "" }));
    }
  }

  lockToggle.addEventListener("change", () => { state.lockMode = lockToggle.checked; });

  function shape() {
    return state.axes.map((a) => safeList(a.text).length);
  }

  function renderValues() {
    const dims = shape();
    const bps = state.axes.map((a) => safeList(a.text));
    const f = Number(fill.value) || 0;
    if (!state.values || !sameShape(state.values, dims)) state.values = blank(dims, f);
    const rows = dims.length === 1 ? [state.values] : state.values;
    const table = h("table", {},
      h("thead", {}, h("tr", {}, h("th", { class: "rowh" }, dims.length === 1 ? "" : `${state.axes[0].name} ↓ / ${state.axes[1].name} →`),
        (dims.length === 1 ? bps[0] : bps[1]).map((v) => h("th", { scope: "col" }, fmt(v))))),
      h("tbody", {}, rows.map((row, i) =>
        h("tr", {},
          h("th", { class: "rowh", scope: "row" }, dims.length === 1 ? state.axes[0].name : fmt(bps[0][i])),
          row.map((v, j) => {
            const flatIndex = dims.length === 1 ? j : i * dims[1] + j;
            const input = h("input", { type: "number", step: "any", value: String(v),
              "aria-label": dims.length === 1 ? `Cell ${state.axes[0].name} = ${bps[0][j]}`
                : `Cell ${state.axes[0].name} = ${bps[0][i]}, ${state.axes[1].name} = ${bps[1][j]}`,
              class: state.locked.has(flatIndex) ? "locked" : null, dataset: { cell: flatIndex } });
            input.addEventListener("change", () => {
              const val = Number(input.value);
              if (dims.length === 1) state.values[j] = val;
              else state.values[i][j] = val;
            });
            const toggleLock = () => {
              if (state.locked.has(flatIndex)) state.locked.delete(flatIndex);
              else state.locked.add(flatIndex);
              input.classList.toggle("locked", state.locked.has(flatIndex));
              input.title = state.locked.has(flatIndex) ? "locked" : "";
              lockCount.textContent = lockText();
            };
            input.addEventListener("click", () => state.lockMode && toggleLock());
            input.addEventListener("keydown", (e) => {
              if (state.lockMode && (e.key === "l" || e.key === "L")) {
                e.preventDefault();
                toggleLock();
              }
            });
            return h("td", {}, input);
          })))));
    valuesHost.replaceChildren(h("div", { class: "values-grid" }, table), lockCount);
    lockCount.textContent = lockText();
  }

  function lockText() {
    return `${state.locked.size} locked cell(s) — locked cells keep their value and variance.`;
  }

  function renderBaseOptions() {
    baseSelect.replaceChildren(h("option", { value: "" }, state.baseMaps.length ? "— choose —" : "no base maps yet"),
      ...state.baseMaps.map((m) => h("option", { value: String(m.id), selected: m.id === state.baseMapId },
        `#${m.id} ${m.name}`)));
  }

  function applyBaseMap(map) {
    state.baseMapId = map?.id ?? null;
    const info = el.querySelector("[data-base-info]");
    if (!map) {
      if (info) info.textContent = "";
      return;
    }
    if (map.axes?.length) {
      state.axes = map.axes.map((a) => ({ name: a.name, unit: a.unit ?? "", text: a.breakpoints.join(", "), n: a.breakpoints.length }));
      state.values = map.values;
      renderAxes();
    }
    if (info) {
      const lin = map.lineage;
      info.textContent = `${map.axes?.map((a) => `${a.name} (${a.breakpoints.length})`).join(" × ") ?? ""}` +
        (lin?.run_id ? ` · from run #${lin.run_id}, version ${lin.version_id} (${lin.estimator})` : "");
    }
  }

  baseSelect.addEventListener("change", async () => {
    const id = Number(baseSelect.value);
    if (!id) return applyBaseMap(null);
    try {
      applyBaseMap(await api.get(`/api/base-maps/${id}`));
    } catch (err) {
      showError(el, Object.assign(err, { field: "base_map_id" }));
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
      state.baseMapId = map.id;
      renderBaseOptions();
      applyBaseMap(map);
    } catch (err) {
      showError(el, Object.assign(err, { field: "base_map_id" }));
    }
  });

  for (const name of initial.length ? initial : []) addAxis(name);
  if (!state.axes.length && channels.length) {
    addAxis(channels[0].name);
    if (channels.length > 2) addAxis(channels[1].name);
  }
  renderStart();

  return {
    el,
    /** Point the axes at these columns (e.g. after the dataset or mapping changed). */
    setAxes(names) {
      state.axes = [];
      for (const n of names.slice(0, MAX_AXES)) addAxis(n);
    },
    redraw: drawCoverage,
    destroy: () => purge(coverage),
    /** {table, base_map_id, locked}; throws Error with .field on unreadable breakpoints. */
    read() {
      const axes = state.axes.map((a, k) => {
        let breakpoints;
        try {
          breakpoints = parseNumberList(a.text);
        } catch (err) {
          throw Object.assign(new Error(err.message), { field: `table.axes.${k}.breakpoints` });
        }
        if (breakpoints.length < 2) {
          throw Object.assign(new Error("at least two breakpoints are needed"), { field: `table.axes.${k}.breakpoints` });
        }
        return { name: a.name, breakpoints, unit: a.unit || undefined };
      });
      const table = { axes };
      if (state.start === "values" && state.values) table.values = state.values;
      if (state.start === "base" && state.values) table.values = state.values;
      return {
        table,
        base_map_id: state.start === "base" ? state.baseMapId : null,
        locked: state.start === "values" && state.locked.size ? [...state.locked].sort((a, b) => a - b) : null,
      };
    },
  };
}

function safeList(text) {
  try {
    return parseNumberList(text);
  } catch {
    return [];
  }
}

function blank(dims, f) {
  if (dims.length === 1) return Array(dims[0]).fill(f);
  return Array.from({ length: dims[0] }, () => Array(dims[1]).fill(f));
}

function sameShape(values, dims) {
  if (dims.length === 1) return Array.isArray(values) && !Array.isArray(values[0]) && values.length === dims[0];
  return Array.isArray(values?.[0]) && values.length === dims[0] && values[0].length === dims[1];
}
