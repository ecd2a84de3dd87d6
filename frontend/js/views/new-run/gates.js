/**
 * Sample gates of a run: reject samples of a channel outside a range, changing faster than a
 * rate, or for some seconds after it crosses a threshold (holdoff). One row per gate, as the
 * API's `config.gates[k]`, so its errors land next to the control.
 */
import { h, icon, ICONS, withUnit } from "../../dom.js";
import { channels } from "./state.js";

const GATE_TYPES = ["range", "rate", "holdoff"];

/**
 * The gates editor: `list` holds the gates as typed ({type, channel, …} with string values),
 * starting from the draft's; read() gives the API's gate specs.
 */
export function gatesEditor(view, saved = []) {
  const list = [];
  for (const g of saved) if (g && typeof g === "object") list.push({ ...g });
  const el = h("div", { class: "gates-editor" });
  const render = () => {
    const chans = channels(view);
    el.replaceChildren(...list.map((g, k) => gateRow(g, k, chans, { list, render })));
  };
  const addButton = h(
    "button",
    {
      type: "button",
      class: "small",
      "data-add-gate": "",
      onclick: () => {
        list.push({ type: "range" });
        render();
      },
    },
    icon(ICONS.plus),
    "Add gate",
  );
  return { el, addButton, list, render, read: () => list.map(gateSpec) };
}

/** A gate as the API takes it: numbers parsed, empty fields left out. */
function gateSpec(g) {
  const num = (v) => (v === undefined || v === "" ? undefined : Number(v));
  if (g.type === "range")
    return { type: "range", channel: g.channel, min: num(g.min), max: num(g.max) };
  if (g.type === "rate") return { type: "rate", channel: g.channel, max_abs: num(g.max_abs) };
  const side = g.when === "above" ? "above" : "below";
  return { type: "holdoff", channel: g.channel, [side]: num(g.threshold), seconds: num(g.seconds) };
}

function gateRow(g, k, chans, { list, render }) {
  const pre = `config.gates.${k}`;
  const field = (...children) => h("div", { class: "field", style: { margin: 0 } }, ...children);
  const set = (key) => (e) => {
    g[key] = e.target.value;
  };
  const num = (key, label) =>
    field(
      h("label", { for: `gate-${k}-${key}` }, label),
      h("input", {
        type: "number",
        step: "any",
        id: `gate-${k}-${key}`,
        name: `${pre}.${key}`,
        value: g[key] ?? "",
        oninput: set(key),
      }),
    );
  const type = h(
    "select",
    {
      id: `gate-${k}-type`,
      name: `${pre}.type`,
      onchange: (e) => {
        g.type = e.target.value;
        render();
      },
    },
    GATE_TYPES.map((t) => h("option", { value: t, selected: t === g.type }, t)),
  );
  const chan = h(
    "select",
    { id: `gate-${k}-channel`, name: `${pre}.channel`, onchange: set("channel") },
    chans.map((c) =>
      h("option", { value: c.name, selected: c.name === g.channel }, withUnit(c.name, c.unit)),
    ),
  );
  g.channel = g.channel ?? chans[0]?.name;
  let params;
  if (g.type === "range") params = [num("min", "min"), num("max", "max"), h("div")];
  else if (g.type === "rate") params = [num("max_abs", "max |d/dt| per s"), h("div"), h("div")];
  else {
    const when = h(
      "select",
      { id: `gate-${k}-when`, onchange: set("when") },
      h("option", { value: "below", selected: g.when !== "above" }, "below"),
      h("option", { value: "above", selected: g.when === "above" }, "above"),
    );
    params = [
      field(h("label", { for: `gate-${k}-when` }, "when"), when),
      num("threshold", "threshold"),
      num("seconds", "reject for [s]"),
    ];
  }
  return h(
    "div",
    { class: "gate-row", "data-gate": k },
    field(h("label", { for: `gate-${k}-type` }, "Gate"), type),
    field(h("label", { for: `gate-${k}-channel` }, "Channel"), chan),
    ...params,
    h(
      "button",
      {
        type: "button",
        class: "ghost icon",
        "aria-label": `Remove gate ${k + 1}`,
        onclick: () => {
          list.splice(k, 1);
          render();
        },
      },
      icon(ICONS.x),
    ),
  );
}
