/**
 * New run from an ECU map (/runs/new?ecu=ID&map=NAME, the ECU view's "Adapt this map"):
 * the table's axes, breakpoints and units, the limits and the current values as the starting
 * map come from GET /api/ecus/{id}/maps/{name}/template?dataset_id=N, fetched again whenever
 * the dataset changes, since the axes' input quantities are matched to that dataset's
 * channels by name (tool suffixes such as `\ETK:1` ignored). A quantity without a channel is
 * listed with a column picker; picking one keeps the A2L breakpoints. The run is started with
 * `calibration: {ecu_id, map}`, which its CDFX and patched-image exports need.
 * See docs/calibration.md#dashboard.
 */
import { api } from "../../api.js";
import { fmt, h, withUnit } from "../../dom.js";
import { channels } from "./state.js";

/** The ECU map named by the URL, or null. */
export function ecuFromQuery(q) {
  const ecuId = Number(q.get("ecu"));
  const map = q.get("map");
  if (!Number.isInteger(ecuId) || ecuId < 1 || !map) return null;
  return { ecuId, map, ecu: null, summary: null, template: null, error: null, assign: new Map() };
}

/**
 * Fetch the ECU, the map and its template for the chosen dataset, and point the form's axes
 * at the matched columns. Problems are shown in the banner; the form stays usable.
 */
export async function loadTemplate(view) {
  const { state, ctx, ecu: e } = view;
  if (!e) return;
  const path = `/api/ecus/${e.ecuId}/maps/${encodeURIComponent(e.map)}`;
  try {
    if (!e.summary) {
      [e.ecu, e.summary] = await Promise.all([
        api.get(`/api/ecus/${e.ecuId}`, { signal: ctx.signal }),
        api.get(path, { signal: ctx.signal }),
      ]);
    }
    e.template = await api.get(`${path}/template`, {
      query: { dataset_id: state.datasetId },
      signal: ctx.signal,
    });
    e.error = null;
  } catch (err) {
    if (err.name === "AbortError") return; // the form was left
    e.template = null;
    e.error = err.message;
    return;
  }
  // Columns from the URL (a reload) stand for quantities the API could not match.
  const fromUrl = state.axes;
  e.template.table.axes.forEach((_, k) => {
    const q = quantityOf(e, k);
    if (!e.assign.has(q) && !matchedOf(e)[q] && hasChannel(view, fromUrl[k])) {
      e.assign.set(q, fromUrl[k]);
    }
  });
  e.pending = null;
  state.axes = columns(view);
  // A channel named like the map is its measured output.
  if (e.template.output && hasChannel(view, e.template.output)) state.signals.y = e.template.output;
}

/** The A2L input quantity of axis k. */
function quantityOf(e, k) {
  const axis = e.template.table.axes[k];
  return axis.quantity ?? e.summary?.axes?.[k]?.input_quantity ?? axis.name;
}

/** The template's breakpoints of an axis; [] when neither the A2L nor the values give them. */
function breakpointsOf(axis) {
  const bps = axis.breakpoints ?? [];
  return bps.every((v) => Number.isFinite(v)) ? bps : [];
}

function matchedOf(e) {
  return e.template?.channels?.matched ?? {};
}

function hasChannel(view, name) {
  return Boolean(name) && channels(view).some((c) => c.name === name);
}

/**
 * The column of each axis: the one picked for its quantity, else the matched channel, else
 * the first channel no other axis uses (flagged in the banner until a column is picked).
 */
function columns(view) {
  const e = view.ecu;
  const chans = channels(view).map((c) => c.name);
  const out = e.template.table.axes.map((_, k) => {
    const q = quantityOf(e, k);
    const col = e.assign.get(q) ?? matchedOf(e)[q] ?? null;
    return chans.includes(col) ? col : null;
  });
  const used = new Set(out.filter(Boolean));
  return out.map((col) => {
    if (col) return col;
    const free = chans.find((c) => !used.has(c)) ?? chans[0];
    used.add(free);
    return free;
  });
}

/**
 * The grid editor's starting point (a gridEditor snapshot): the template's breakpoints and
 * units on the chosen columns, its base map as typed start values. Null without a template.
 */
export function prefillGrid(view) {
  const e = view.ecu;
  if (!e?.template) return null;
  if (e.pending) return e.pending;
  const names = columns(view);
  const base = e.template.base_map;
  return {
    axes: e.template.table.axes.map((a, k) => ({
      name: names[k],
      unit: a.unit ?? "",
      text: breakpointsOf(a).join(", "),
      n: breakpointsOf(a).length || e.summary?.axes?.[k]?.points || 8,
    })),
    start: base?.values ? "values" : "constant",
    values: base?.values ?? null,
    locked: [],
    slice: 0,
    baseMapId: null,
  };
}

/** `calibration` of the run body (single runs of table estimators), or null. */
export function calibrationOf(view) {
  const e = view.ecu;
  return e?.template ? { ecu_id: e.ecuId, map: e.map } : null;
}

/** The banner above the form: the map, its unit and limits, and how its axes were matched. */
export function renderEcuBanner(view) {
  const e = view.ecu;
  const host = view.hosts.ecu;
  if (!e) {
    host.replaceChildren();
    return;
  }
  const link = h("a", { href: `/ecus/${e.ecuId}?map=${encodeURIComponent(e.map)}` }, e.map);
  if (!e.template) {
    host.replaceChildren(
      h(
        "div",
        { class: "banner error", role: "alert", "data-ecu-banner": "" },
        "Cannot adapt ",
        link,
        `: ${e.error ?? "the map could not be loaded."}`,
      ),
    );
    return;
  }
  const t = e.template.table;
  const [lo, hi] = t.limits ?? [null, null];
  const unit = t.output_unit ?? "";
  const names = view.state.grid?.snapshot().axes.map((a) => a.name) ?? columns(view);
  const unmatched = new Set(e.template.channels?.unmatched ?? []);
  host.replaceChildren(
    h(
      "div",
      { class: "banner info ecu-banner", "data-ecu-banner": "" },
      h(
        "div",
        {},
        "Adapting ",
        link,
        ` of ECU ${e.ecu?.name ?? `#${e.ecuId}`}`,
        unit ? ` · output in ${unit}` : "",
        ` · limits ${fmt(lo)} … ${fmt(hi)}${unit ? ` ${unit}` : ""}`,
        e.template.base_map ? " · starts from the ECU's current values" : "",
        ". Exports are clamped to the limits and rounded to what the ECU stores.",
      ),
      h(
        "ul",
        { class: "ecu-axes", "data-ecu-axes": "" },
        t.axes.map((a, k) => axisMatch(view, k, a, names[k], unmatched)),
      ),
      t.axes.some((a) => !breakpointsOf(a).length)
        ? h(
            "div",
            { "data-ecu-no-breakpoints": "" },
            "Neither the A2L nor the values give every axis its points: fit them to the data " +
              "below, at most as many as the ECU holds.",
          )
        : null,
    ),
  );
}

/** "quantity → column", with a picker when the quantity has no channel of its name. */
function axisMatch(view, k, axis, column, unmatched) {
  const e = view.ecu;
  const q = quantityOf(e, k);
  const matched = matchedOf(e)[q];
  if (matched && !unmatched.has(q) && !e.assign.has(q)) {
    return h(
      "li",
      { dataset: { quantity: q, matched: "true" } },
      h("code", {}, withUnit(q, axis.unit)),
      " → ",
      h("code", {}, matched),
    );
  }
  const id = `ecu-axis-${k}`;
  const select = h(
    "select",
    { id, "data-ecu-axis": k },
    channels(view).map((c) =>
      h("option", { value: c.name, selected: c.name === column }, withUnit(c.name, c.unit)),
    ),
  );
  select.addEventListener("change", () => assignColumn(view, k, select.value));
  return h(
    "li",
    { dataset: { quantity: q, matched: "false" } },
    h(
      "label",
      { for: id },
      h("code", {}, withUnit(q, axis.unit)),
      " has no channel of its name: use",
    ),
    select,
  );
}

/** A column picked for axis k: the grid keeps its breakpoints and start values. */
function assignColumn(view, k, column) {
  const { state } = view;
  const e = view.ecu;
  e.assign.set(quantityOf(e, k), column);
  const snap = state.grid?.snapshot() ?? prefillGrid(view);
  snap.axes[k] = { ...snap.axes[k], name: column };
  e.pending = snap;
  state.axes = snap.axes.map((a) => a.name);
  state.grid?.destroy();
  state.grid = null;
  view.renderAll();
  view.syncUrl();
  view.saveDraft();
}
