/**
 * One characteristic of an ECU (GET /api/ecus/{id}/maps/{name}): what the A2L says about it
 * (type, unit, limits, datatype, conversion, record layout, address, each axis' input
 * quantity, unit and points) and its current values — a heatmap for a MAP, a line for a CURVE,
 * the number for a VALUE — with the axes named after their input quantities and the colour
 * bar in the characteristic's unit. "Adapt this map" opens New run prefilled from the map
 * (docs/calibration.md#dashboard); "Save as base map" keeps the current values as a base map.
 */
import { api, showError } from "../../api.js";
import { EVT } from "../../constants.js";
import { card, fmt, h, icon, ICONS, toast, withUnit } from "../../dom.js";
import { MapPlot } from "../../map-plot.js";
import { SCOPE } from "../../scopes.js";
import { shapeText } from "./browser.js";

/** Characteristics with axes: what a run's table can adapt. */
const ADAPTABLE = new Set(["MAP", "CURVE"]);

/**
 * The plot frame of the values: axes named after the A2L input quantities (or "index" for
 * the rows and columns of a VAL_BLK), in the units the values came with.
 */
export function frameOf(summary, values) {
  const axes = values.axes.length
    ? values.axes.map((breakpoints, k) => ({
        name: summary.axes[k]?.input_quantity || `axis ${k + 1}`,
        unit: values.axis_units?.[k] || summary.axes[k]?.unit || "",
        breakpoints,
      }))
    : blockAxes(values.values);
  return { axes, values: values.values };
}

/** Index axes for a VAL_BLK (a vector, or a matrix of rows × columns). */
function blockAxes(values) {
  if (!Array.isArray(values)) return [];
  const index = (n) => [...Array(n).keys()];
  if (!Array.isArray(values[0]))
    return [{ name: "index", unit: "", breakpoints: index(values.length) }];
  return [
    { name: "row", unit: "", breakpoints: index(values.length) },
    { name: "column", unit: "", breakpoints: index(values[0].length) },
  ];
}

/**
 * @param {HTMLElement} host
 * @param {{ecu: object, name: string, signal: AbortSignal, current: () => boolean}} opts
 *   current: false once another characteristic was picked (this answer is then dropped)
 * @returns {Promise<() => void>} cleanup
 */
export async function renderDetail(host, { ecu, name, signal, current }) {
  host.replaceChildren(h("div", { class: "loading" }, `Loading ${name}…`));
  let c;
  try {
    c = await api.get(`/api/ecus/${ecu.id}/maps/${encodeURIComponent(name)}`, { signal });
  } catch (err) {
    if (err.name !== "AbortError" && current()) {
      host.replaceChildren(h("div", { class: "banner error", role: "alert" }, err.message));
    }
    return () => {};
  }
  if (!current()) return () => {};
  const unit = c.values?.unit || c.unit || "";
  const plotEl = h("div", { class: "plot map", "data-plot": "ecu-map" });
  const adapt = ADAPTABLE.has(c.type)
    ? h(
        "a",
        {
          class: "button primary",
          href: `/runs/new?ecu=${ecu.id}&map=${encodeURIComponent(c.name)}`,
          "data-adapt": "",
          "data-needs": SCOPE.run,
        },
        icon(ICONS.play),
        "Adapt this map",
      )
    : null;
  const baseButton =
    c.values && ADAPTABLE.has(c.type)
      ? h(
          "button",
          {
            type: "button",
            "data-save-base": "",
            "data-needs": SCOPE.admin,
            onclick: () => saveBase(),
          },
          icon(ICONS.tag),
          "Save as base map",
        )
      : null;
  const errorHost = h("div", { class: "banner error", "data-form-error": "", hidden: true });
  const body = h(
    "div",
    { class: "stack" },
    h("p", { class: "help", style: { margin: 0 } }, c.description || "No description."),
    valuesPart(c, plotEl, unit),
    facts(c),
    axesTable(c),
    errorHost,
  );
  host.replaceChildren(
    card({
      title: c.name,
      hint: `${c.type} · ${shapeText(c.shape)}${unit ? ` · ${unit}` : ""}`,
      actions: [baseButton, adapt],
      body,
      cls: "ecu-detail",
    }),
  );
  let plot = null;
  const draw = () => plot?.render(frameOf(c, c.values));
  if (c.values && c.type !== "VALUE") {
    plot = new MapPlot(plotEl, { kind: "value", unit, label: c.name });
    draw();
  }
  window.addEventListener(EVT.themeChange, draw);

  async function saveBase() {
    try {
      const map = await api.post(
        `/api/ecus/${ecu.id}/maps/${encodeURIComponent(c.name)}/base-map`,
        undefined,
      );
      toast(`Saved base map #${map.id}.`);
    } catch (err) {
      showError(body, err);
    }
  }

  return () => {
    window.removeEventListener(EVT.themeChange, draw);
    plot?.destroy();
  };
}

/** The values: the plot, the number of a VALUE, or a note that no values file was given. */
function valuesPart(c, plotEl, unit) {
  if (!c.values) {
    return h(
      "div",
      { class: "banner info", "data-no-values": "" },
      "This ECU has no values file: add its HEX, S19, DCM or CDFX to see the current values.",
    );
  }
  if (c.type === "VALUE") {
    const v = Array.isArray(c.values.values) ? c.values.values[0] : c.values.values;
    return h(
      "div",
      { class: "metric", "data-value": "" },
      h("div", { class: "k" }, "Current value"),
      h("div", { class: "v" }, fmt(v), h("span", { class: "u" }, unit)),
    );
  }
  return plotEl;
}

/** Key facts from the A2L as a definition list. */
function facts(c) {
  const [lo, hi] = c.limits ?? [null, null];
  const cm = c.compu_method ?? {};
  const row = (label, key, value) => [
    h("dt", {}, label),
    h("dd", { dataset: { fact: key } }, value),
  ];
  return h(
    "dl",
    { class: "kv ecu-facts" },
    row("Unit", "unit", c.unit || "–"),
    row("Limits", "limits", `${fmt(lo)} … ${fmt(hi)}${c.unit ? ` ${c.unit}` : ""}`),
    row("Datatype", "datatype", `${c.datatype}${c.byte_order ? ` · ${c.byte_order}` : ""}`),
    row("Conversion", "conversion", `${cm.name ?? "–"}${cm.kind ? ` (${cm.kind})` : ""}`),
    row("Record layout", "record-layout", c.record_layout ?? "–"),
    row(
      "Address",
      "address",
      Number.isFinite(c.address) ? `0x${c.address.toString(16).toUpperCase()}` : "–",
    ),
  );
}

/** One row per axis: attribute, input quantity, unit, points, limits, conversion. */
function axesTable(c) {
  if (!c.axes?.length) return null;
  return h(
    "div",
    { class: "table-wrap" },
    h(
      "table",
      { class: "data", "data-axes-table": "" },
      h(
        "thead",
        {},
        h(
          "tr",
          {},
          h("th", { scope: "col" }, "Axis"),
          h("th", { scope: "col" }, "Input quantity"),
          h("th", { scope: "col" }, "Kind"),
          h("th", { scope: "col", class: "num" }, "Points"),
          h("th", { scope: "col" }, "Limits"),
        ),
      ),
      h(
        "tbody",
        {},
        c.axes.map((a, k) =>
          h(
            "tr",
            { dataset: { axis: k } },
            h("td", {}, "XYZUVW"[k] ?? String(k + 1)),
            h("td", { class: "wrap" }, h("code", {}, withUnit(a.input_quantity, a.unit))),
            h("td", {}, a.attribute),
            h("td", { class: "num" }, String(a.points)),
            h("td", {}, `${fmt(a.limits?.[0])} … ${fmt(a.limits?.[1])}`),
          ),
        ),
      ),
    ),
  );
}
