/**
 * The sweep section (?mode=sweep): one row per setting to vary, picked from the estimator's
 * schema, each a list of values or a range drawn from; the sample size and seed; the metric
 * the runs are ranked by. The rows live in `state.sweep` (and so in the draft).
 */
import { SELECT } from "../../constants.js";
import { h, icon, ICONS, metricLabel } from "../../dom.js";
import { selectedEstimators } from "./state.js";
import { metricsFor, orderFor, sweepKeys, sweepSize } from "./sweep-request.js";

/** Settings a new sweep row offers first, when the estimator has them. */
const SWEEP_FIRST = ["sigma_w", "sigma_v", "p0", "forgetting", "mu", "gamma", "k"];

/** A default of the catalog at a dotted key ("sensor.lag"), or undefined. */
function defaultAt(defaults, key) {
  return key
    .split(".")
    .reduce((n, k) => (n && typeof n === "object" ? n[k] : undefined), defaults ?? {});
}

/** A new row: the first preferred setting not swept yet (else any free one). */
function newRow(sw, keys) {
  const used = new Set(sw.rows.map((r) => r.key));
  const free = keys.filter((k) => !used.has(k.key));
  const pick =
    SWEEP_FIRST.map((name) => free.find((k) => k.key === name)).find(Boolean) ?? free[0] ?? keys[0];
  return {
    key: pick.key,
    kind: "values",
    values: "",
    min: "",
    max: "",
    scale: "linear",
    integer: false,
  };
}

/** Draw the section (hidden outside sweep mode, which also renumbers the options section). */
export function renderSweep(view) {
  const { state, hosts } = view;
  const host = hosts.sweep;
  const on = state.mode === "sweep";
  hosts.sweepSection.hidden = !on;
  hosts.optionsSection.querySelector(".n").textContent = on ? "7" : "6";
  if (!on) return;
  const est = selectedEstimators(view)[0];
  const sw = state.sweep;
  if (!est) {
    host.replaceChildren(h("p", { class: "help" }, "Pick an estimator first."));
    return;
  }
  const keys = sweepKeys(est);
  if (!keys.length) {
    host.replaceChildren(
      h("p", { class: "help" }, `${est.name} has no numeric settings to sweep.`),
    );
    return;
  }
  if (sw.estimator !== est.name) {
    sw.rows = sw.rows.filter((r) => keys.some((k) => k.key === r.key));
    if (!metricsFor(est).includes(sw.metric)) {
      sw.metric = metricsFor(est)[0];
      sw.order = orderFor(sw.metric);
    }
    sw.estimator = est.name;
  }
  if (!sw.rows.length) sw.rows.push(newRow(sw, keys));
  const count = h("p", { class: "sweep-count", "data-sweep-count": "", "aria-live": "polite" });
  const refresh = () => {
    count.textContent = sweepSize(sw).text;
    view.updateSubmit();
  };
  // Redraw, then put the focus back where it was (the redraw replaced the control).
  const redraw = (focus) => {
    renderSweep(view);
    host.querySelector(focus)?.focus();
  };
  const rows = sw.rows.map((row, k) => sweepRow({ est, keys, sw, row, k, refresh, redraw }));
  host.replaceChildren(
    h(
      "p",
      { class: "help", style: { marginTop: 0 } },
      "Every other setting is taken from the configuration above. Values make a grid (every combination); ",
      "ranges are drawn from at random — give the number of samples.",
    ),
    h("div", { class: "field", "data-field": "parameters" }, rows),
    h(
      "button",
      {
        type: "button",
        class: "small",
        "data-add-sweep-param": "",
        disabled: keys.length <= sw.rows.length,
        onclick: () => {
          sw.rows.push(newRow(sw, keys));
          redraw(SELECT.id(`sweep-param-${sw.rows.length - 1}`));
        },
      },
      icon(ICONS.plus),
      "Add parameter",
    ),
    count,
    sweepSettings(est, sw, refresh),
  );
  refresh();
}

/** Row k: the setting, values or range, and its remove button. */
function sweepRow({ est, keys, sw, row, k, refresh, redraw }) {
  const info = keys.find((x) => x.key === row.key) ?? keys[0];
  row.key = info.key;
  if (info.type === "enum") row.kind = "values";
  const param = h(
    "select",
    {
      id: `sweep-param-${k}`,
      onchange: (e) => {
        row.key = e.target.value;
        redraw(SELECT.id(`sweep-param-${k}`));
      },
    },
    keys.map((x) =>
      h("option", { value: x.key, selected: x.key === row.key }, `${x.label} · ${x.key}`),
    ),
  );
  const kind = h(
    "select",
    {
      id: `sweep-kind-${k}`,
      disabled: info.type === "enum",
      onchange: (e) => {
        row.kind = e.target.value;
        redraw(SELECT.id(`sweep-kind-${k}`));
      },
    },
    h("option", { value: "values", selected: row.kind !== "range" }, "Values"),
    h("option", { value: "range", selected: row.kind === "range" }, "Range (random)"),
  );
  const def = defaultAt(est.defaults, row.key);
  const hasDefault = def !== undefined && def !== null && typeof def !== "object";
  const about = [info.bounds, hasDefault ? `default ${def}` : ""].filter(Boolean).join(" · ");
  const set = (prop) => (e) => {
    row[prop] = e.target.type === "checkbox" ? e.target.checked : e.target.value;
    refresh();
  };
  const values =
    row.kind === "range"
      ? rangeFields(row, info, k, about, set)
      : valuesField(row, info, k, about, set);
  const remove = () => {
    sw.rows.splice(k, 1);
    if (!sw.rows.length) sw.rows.push(newRow(sw, keys));
    redraw("[data-add-sweep-param]");
  };
  return h(
    "div",
    { class: "sweep-param", "data-sweep-row": k },
    h("div", { class: "field" }, h("label", { for: `sweep-param-${k}` }, "Parameter"), param),
    h("div", { class: "field" }, h("label", { for: `sweep-kind-${k}` }, "Give"), kind),
    values,
    h(
      "button",
      {
        type: "button",
        class: "ghost icon",
        "aria-label": `Remove parameter ${k + 1}`,
        style: { marginTop: "22px" },
        onclick: remove,
      },
      icon(ICONS.x),
    ),
  );
}

/** Min, max, scale and "integers" of a range drawn from. */
function rangeFields(row, info, k, about, set) {
  const field = `parameters.${row.key}`;
  const num = (prop, label, extra = {}) =>
    h(
      "div",
      { class: "field" },
      h("label", { for: `sweep-${prop}-${k}` }, label),
      h("input", {
        type: "number",
        step: "any",
        id: `sweep-${prop}-${k}`,
        name: `${field}.${prop}`,
        value: row[prop] ?? "",
        autocomplete: "off",
        oninput: set(prop),
        ...extra,
      }),
    );
  return h(
    "div",
    {},
    h(
      "div",
      { class: "sweep-range" },
      num("min", "Min", { "data-field": field }),
      num("max", "Max"),
      h(
        "div",
        { class: "field" },
        h("label", { for: `sweep-scale-${k}` }, "Scale"),
        h(
          "select",
          { id: `sweep-scale-${k}`, name: `${field}.scale`, onchange: set("scale") },
          h("option", { value: "linear", selected: row.scale !== "log" }, "linear"),
          h("option", { value: "log", selected: row.scale === "log" }, "log"),
        ),
      ),
      h(
        "label",
        { class: "check", for: `sweep-integer-${k}` },
        h("input", {
          type: "checkbox",
          id: `sweep-integer-${k}`,
          name: `${field}.integer`,
          checked: row.integer || info.type === "integer",
          disabled: info.type === "integer",
          onchange: set("integer"),
        }),
        "integers",
      ),
    ),
    about ? h("div", { class: "help" }, about) : null,
  );
}

/** The values to try, comma-separated (one or more of the options of an enum). */
function valuesField(row, info, k, about, set) {
  const isEnum = info.type === "enum";
  return h(
    "div",
    { class: "field" },
    h("label", { for: `sweep-values-${k}` }, "Values"),
    h("input", {
      type: "text",
      id: `sweep-values-${k}`,
      name: `parameters.${row.key}`,
      class: "mono",
      value: row.values ?? "",
      autocomplete: "off",
      inputmode: isEnum ? null : "decimal",
      oninput: set("values"),
      placeholder: isEnum ? info.options.join(", ") : "e.g. 0.5, 1, 2",
    }),
    h(
      "div",
      { class: "help" },
      isEnum ? `one or more of ${info.options.join(", ")}` : "comma-separated",
      about ? ` · ${about}` : "",
    ),
  );
}

/** Samples, seed, the ranking metric and its order. */
function sweepSettings(est, sw, refresh) {
  const orderSelect = h(
    "select",
    {
      id: "sweep-order",
      name: "order",
      onchange: (e) => {
        sw.order = e.target.value;
      },
    },
    h("option", { value: "min", selected: sw.order !== "max" }, "Lowest first"),
    h("option", { value: "max", selected: sw.order === "max" }, "Highest first"),
  );
  const metricSelect = h(
    "select",
    {
      id: "sweep-metric",
      name: "metric",
      onchange: (e) => {
        sw.metric = e.target.value;
        sw.order = orderFor(sw.metric);
        orderSelect.value = sw.order;
      },
    },
    metricsFor(est).map((m) =>
      h("option", { value: m, selected: m === sw.metric }, `${metricLabel(m)} (${m})`),
    ),
  );
  const whole = (id, min, value, extra) =>
    h("input", {
      type: "number",
      id,
      name: id.replace("sweep-", ""),
      min,
      step: "1",
      value,
      autocomplete: "off",
      ...extra,
    });
  return h(
    "div",
    { class: "fields" },
    h(
      "div",
      { class: "field" },
      h("label", { for: "sweep-samples" }, "Samples"),
      whole("sweep-samples", "1", sw.samples ?? "", {
        placeholder: "the full grid",
        oninput: (e) => {
          sw.samples = e.target.value;
          refresh();
        },
      }),
      h("div", { class: "help" }, "Random draws; empty: every combination of the values."),
    ),
    h(
      "div",
      { class: "field" },
      h("label", { for: "sweep-seed" }, "Seed"),
      whole("sweep-seed", "0", sw.seed ?? "0", {
        oninput: (e) => {
          sw.seed = e.target.value;
          refresh();
        },
      }),
    ),
    h("div", { class: "field" }, h("label", { for: "sweep-metric" }, "Rank by"), metricSelect),
    h("div", { class: "field" }, h("label", { for: "sweep-order" }, "Best"), orderSelect),
  );
}
