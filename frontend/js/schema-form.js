/**
 * A form generated from an estimator's JSON schema (pydantic's model_json_schema): one
 * labelled control per property, the paper's default filled in, nested sections as fieldsets
 * (optional sections behind a switch). read() returns the config object and checks numbers
 * against the schema's bounds (the API checks again); controls are named by their dotted path
 * ("config.sensor.lag") so errors land next to them.
 */
import { SEL } from "./constants.js";
import { h, parseNumberList, withUnit } from "./dom.js";

/**
 * @param {object} schema      JSON schema of the config model
 * @param {object} opts
 * @param {object} [opts.defaults]  the catalog's defaults (override schema defaults)
 * @param {object} [opts.values]    values to start from (e.g. a previous run's config)
 * @param {Set<string>} [opts.hide] top-level properties not shown (filled elsewhere)
 * @param {{name, unit}[]} [opts.channels] dataset channels, offered for *_channel properties
 * @param {string} [opts.prefix]    name prefix, default "config"
 * @param {string} [opts.idPrefix]  unique id prefix when several forms share a page
 * @param {string} [opts.valuesSource] where opts.values come from (shown as each such field's
 *   source instead of the schema's, e.g. "scenario nox-sdmp" or "run #12")
 */
export function schemaForm(
  schema,
  {
    defaults = {},
    values = {},
    hide = new Set(),
    channels = [],
    prefix = "config",
    idPrefix = "cfg",
    valuesSource = "",
  } = {},
) {
  const readers = [];
  const el = h("div", { class: "schema-form" });
  const root = resolve(schema, schema);
  const props = Object.entries(root.properties ?? {}).filter(([key]) => !hide.has(key));
  const simple = [];
  const sections = [];
  for (const [key, prop] of props) {
    const start =
      key in values ? values[key] : key in defaults ? defaults[key] : resolve(prop, schema).default;
    const origin = key in values ? valuesSource : "";
    const built = control(schema, prop, [key], start, { channels, prefix, idPrefix, origin });
    readers.push([key, built.read]);
    (built.section ? sections : simple).push(built.el);
  }
  el.append(h("div", { class: "fields" }, simple), ...sections);
  if (!props.length) el.append(h("p", { class: "help" }, "Nothing to configure."));
  return {
    el,
    /** The config object (throws Error with .field for an unreadable entry). */
    read() {
      const out = {};
      for (const [key, read] of readers) {
        const v = read();
        if (v !== undefined) out[key] = v;
      }
      return out;
    },
  };
}

function resolve(node, schema) {
  let n = node;
  while (n && n.$ref) {
    const path = n.$ref.replace(/^#\//, "").split("/");
    n = path.reduce((acc, k) => acc?.[k], schema);
  }
  return n ?? {};
}

/** anyOf [X, {type: null}] → {inner: X, nullable: true}. */
function unwrap(prop, schema) {
  const p = resolve(prop, schema);
  const options = p.anyOf ?? p.oneOf;
  if (!options) return { inner: p, nullable: false, alternatives: [] };
  const nonNull = options.map((o) => resolve(o, schema)).filter((o) => o.type !== "null");
  const nullable = nonNull.length < options.length;
  const merged = {
    ...nonNull[0],
    title: p.title,
    description: p.description ?? nonNull[0]?.description,
    default: p.default,
  };
  return { inner: merged, nullable, alternatives: nonNull };
}

const GREEK = {
  sigma: "σ",
  theta: "θ",
  gamma: "γ",
  eps: "ε",
  kappa: "κ",
  mu: "μ",
  lambda: "λ",
  ell: "ℓ",
  rho: "ρ",
  tau: "τ",
};

/** Label of a property: its own title unless that is just the key, then the key with symbols. */
function titleOf(key, p) {
  if (p.title && p.title.toLowerCase().replaceAll(" ", "_") !== key.toLowerCase()) return p.title;
  const m = /^(sigma|theta|gamma|eps|kappa|mu|lambda|ell|rho|tau)_?([a-z0-9]*)$/i.exec(key);
  if (m) return `${GREEK[m[1].toLowerCase()]}${m[2]}`;
  if (/^[pk]\d+$/i.test(key)) return key.toUpperCase();
  return humanise(key);
}

function humanise(key) {
  return key.replaceAll("_", " ").replace(/^\w/, (c) => c.toUpperCase());
}

/**
 * What a cleared number or list field means: none where the schema allows it, an empty list
 * where that is the default, else an error on the field. Never a silent server default: the
 * run's record would not say what it ran with.
 */
function blankValue(prop, inner, nullable, label, name) {
  if (nullable) return null;
  const fallback = prop.default ?? inner.default;
  if (Array.isArray(fallback) && fallback.length === 0) return [];
  const shown = Array.isArray(fallback) ? fallback.join(", ") : fallback;
  const hint = fallback === undefined ? "" : ` (the default is ${shown})`;
  throw Object.assign(new Error(`${label}: give a value${hint}`), { field: name });
}

function control(schema, prop, path, start, opts) {
  const { inner, nullable, alternatives } = unwrap(prop, schema);
  const key = path.at(-1);
  const name = [opts.prefix, ...path].join(".");
  const id = `${opts.idPrefix}-${path.join("-")}`.replace(/[^\w-]/g, "_");
  const label = titleOf(key, inner);
  const help = inner.description ?? "";
  // Where the default comes from (the config schema's "source": a paper's equation or
  // table, or "mapwise default" where no paper gives the value).
  const own = prop.source ?? resolve(prop, schema).source ?? inner.source ?? "";
  const source = opts.origin ? `From the ${opts.origin}` : own ? `Default: ${own}` : "";
  const numberOrArray =
    alternatives.some((a) => a.type === "array") &&
    alternatives.some((a) => a.type === "number" || a.type === "integer");

  if (inner.type === "object" && inner.properties)
    return objectControl(schema, inner, path, start, nullable, opts, { name, label, help });

  let input;
  let read;
  if (inner.enum) {
    input = h(
      "select",
      { id, name },
      inner.enum.map((v) => h("option", { value: String(v), selected: v === start }, String(v))),
    );
    read = () => {
      const raw = input.value;
      const found = inner.enum.find((v) => String(v) === raw);
      return found === undefined ? raw : found;
    };
  } else if (inner.type === "boolean") {
    input = h("input", { type: "checkbox", id, name, checked: Boolean(start) });
    read = () => input.checked;
    return wrap(h("label", { class: "check", for: id }, input, label), help, key, {
      checkbox: true,
      read,
      source,
    });
  } else if (inner.type === "string" && /_channel$/.test(key) && opts.channels.length) {
    input = h(
      "select",
      { id, name },
      opts.channels.some((c) => c.name === start)
        ? null
        : h("option", { value: start ?? "" }, start ? `${start} (not in dataset)` : "—"),
      opts.channels.map((c) =>
        h("option", { value: c.name, selected: c.name === start }, withUnit(c.name, c.unit)),
      ),
    );
    read = () => input.value || undefined;
  } else if (inner.type === "array" && resolve(inner.items, schema).enum) {
    // A set of choices (e.g. the EKF's measured outputs): one check box per choice.
    const choices = resolve(inner.items, schema).enum;
    const chosen = new Set(Array.isArray(start) ? start : []);
    const boxes = choices.map((v, i) =>
      h("input", {
        type: "checkbox",
        id: `${id}-${i}`,
        name,
        value: String(v),
        checked: chosen.has(v),
      }),
    );
    input = h(
      "div",
      { class: "checks", role: "group", "aria-label": label, "data-field": name },
      boxes.map((b, i) => h("label", { class: "check", for: b.id }, b, String(choices[i]))),
    );
    read = () => {
      const picked = choices.filter((_, i) => boxes[i].checked);
      const least = inner.minItems ?? 0;
      if (picked.length < least)
        throw Object.assign(new Error(`${label}: pick at least ${least}`), { field: name });
      return picked;
    };
    const title = h("span", { class: "label" }, label, " ", h("code", { class: "help" }, key));
    return wrap(title, help, key, { input, read, source });
  } else if (inner.type === "array" || numberOrArray) {
    const text = Array.isArray(start) ? start.join(", ") : (start ?? "");
    input = h("input", {
      type: "text",
      id,
      name,
      value: String(text),
      class: "mono",
      inputmode: "decimal",
      autocomplete: "off",
      placeholder: nullable
        ? "auto"
        : numberOrArray
          ? "a number, or one per cell"
          : "comma-separated numbers",
    });
    read = () => {
      const raw = input.value.trim();
      if (!raw) return blankValue(prop, inner, nullable, label, name);
      let list;
      try {
        list = parseNumberList(raw);
      } catch (err) {
        throw Object.assign(new Error(`${label}: ${err.message}`), { field: name });
      }
      if (numberOrArray && list.length === 1) return list[0];
      return list;
    };
  } else if (inner.type === "number" || inner.type === "integer") {
    input = h("input", {
      type: "number",
      id,
      name,
      step: inner.type === "integer" ? "1" : "any",
      autocomplete: "off",
      value: start === null || start === undefined ? "" : String(start),
      placeholder: nullable ? "none" : "",
      min: inner.minimum ?? null,
      max: inner.maximum ?? null,
    });
    read = () => {
      const raw = input.value.trim();
      if (raw === "") return blankValue(prop, inner, nullable, label, name);
      const v = Number(raw);
      if (!Number.isFinite(v))
        throw Object.assign(new Error(`${label}: "${raw}" is not a number`), { field: name });
      const problem = outOfBounds(inner, v);
      if (problem)
        throw Object.assign(new Error(`${label}: must be ${problem}, got ${raw}`), { field: name });
      return v;
    };
  } else {
    input = h("input", {
      type: "text",
      id,
      name,
      value: start ?? "",
      autocomplete: "off",
      placeholder: nullable ? "none" : "",
    });
    read = () => (input.value === "" ? (nullable ? null : undefined) : input.value);
  }
  return wrap(h("label", { for: id }, label, " ", h("code", { class: "help" }, key)), help, key, {
    input,
    read,
    range: rangeText(inner),
    source,
  });
}

/** The bound of a JSON-schema number that v breaks, in words (as pydantic says it), or null. */
function outOfBounds(p, v) {
  if (p.type === "integer" && !Number.isInteger(v)) return "a whole number";
  if (p.exclusiveMinimum !== undefined && !(v > p.exclusiveMinimum))
    return `greater than ${p.exclusiveMinimum}`;
  if (p.minimum !== undefined && !(v >= p.minimum)) return `greater than or equal to ${p.minimum}`;
  if (p.exclusiveMaximum !== undefined && !(v < p.exclusiveMaximum))
    return `less than ${p.exclusiveMaximum}`;
  if (p.maximum !== undefined && !(v <= p.maximum)) return `less than or equal to ${p.maximum}`;
  return null;
}

function rangeText(p) {
  const lo =
    p.minimum !== undefined
      ? `≥ ${p.minimum}`
      : p.exclusiveMinimum !== undefined
        ? `> ${p.exclusiveMinimum}`
        : "";
  const hi =
    p.maximum !== undefined
      ? `≤ ${p.maximum}`
      : p.exclusiveMaximum !== undefined
        ? `< ${p.exclusiveMaximum}`
        : "";
  return [lo, hi].filter(Boolean).join(", ");
}

function wrap(labelEl, help, key, { input, read, checkbox = false, range = "", source = "" }) {
  const el = h(
    "div",
    { class: "field", dataset: { key } },
    labelEl,
    checkbox ? null : input,
    help || range ? h("div", { class: "help" }, help, range ? ` (${range})` : "") : null,
    source ? h("div", { class: "help", "data-source": "" }, source) : null,
  );
  return { el, read, section: false };
}

function objectControl(schema, inner, path, start, nullable, opts, { name, label, help }) {
  const id = `${opts.idPrefix}-${path.join("-")}-on`.replace(/[^\w-]/g, "_");
  const readers = [];
  const fields = [];
  const startObj = start && typeof start === "object" ? start : {};
  for (const [k, p] of Object.entries(inner.properties)) {
    const v = k in startObj ? startObj[k] : resolve(p, schema).default;
    const built = control(schema, p, [...path, k], v, opts);
    readers.push([k, built.read]);
    fields.push(built.el);
  }
  const body = h("div", { class: "fields" }, fields);
  const fieldset = h(
    "fieldset",
    { "data-field": name },
    h("legend", {}, label),
    help ? h("div", { class: "help", style: { marginBottom: "8px" } }, help) : null,
    body,
  );
  let toggle = null;
  if (nullable) {
    toggle = h("input", {
      type: "checkbox",
      id,
      checked: start !== null && start !== undefined,
      "aria-controls": `${id}-body`,
    });
    body.id = `${id}-body`;
    const sync = () => {
      body.hidden = !toggle.checked;
    };
    toggle.addEventListener("change", sync);
    sync();
    fieldset
      .querySelector(SEL.legend)
      .replaceChildren(
        h("label", { class: "check", for: id }, toggle, `Use ${label.toLowerCase()}`),
      );
  }
  const read = () => {
    if (toggle && !toggle.checked) return null;
    const out = {};
    for (const [k, r] of readers) {
      const v = r();
      if (v !== undefined) out[k] = v;
    }
    return out;
  };
  return { el: fieldset, read, section: true };
}

/**
 * The settings a sweep can vary: every number (also "a number, or one per cell") and every
 * choice of the schema, sections included under their dotted path ("sensor.lag").
 * @returns {{key: string, label: string, type: "number"|"integer"|"enum", options?: any[], bounds: string}[]}
 */
export function sweepableKeys(schema, { hide = new Set() } = {}) {
  const out = [];
  const walk = (node, path) => {
    for (const [key, prop] of Object.entries(node.properties ?? {})) {
      if (!path.length && hide.has(key)) continue;
      const { inner, alternatives } = unwrap(prop, schema);
      const full = [...path, key];
      const label = path.length
        ? `${path.map(humanise).join(" › ")} › ${titleOf(key, inner)}`
        : titleOf(key, inner);
      const numeric = [inner, ...alternatives].find(
        (a) => a.type === "number" || a.type === "integer",
      );
      if (inner.type === "object" && inner.properties) walk(inner, full);
      else if (inner.enum)
        out.push({ key: full.join("."), label, type: "enum", options: inner.enum, bounds: "" });
      else if (numeric)
        out.push({ key: full.join("."), label, type: numeric.type, bounds: rangeText(numeric) });
    }
  };
  walk(resolve(schema, schema), []);
  return out;
}
