/**
 * The run options section: the run's name, its pace (a real-time multiple, to watch a
 * recorded cycle adapt), how often a map version is kept, the raster on a dataset stored as
 * recorded (its channels on their own timestamps, docs/data-formats.md#multi-rate), and the
 * sample gates.
 */
import { PACES } from "../../constants.js";
import { fmt, h } from "../../dom.js";
import { gatesEditor } from "./gates.js";

/**
 * The options, restored from the draft. Returns {el, name(), read(), gates}: read() gives the
 * service options every run of the form shares (pace, version_every, gates).
 */
export function runOptions(view) {
  const { draft } = view;
  const runName = h("input", {
    type: "text",
    id: "run-name",
    name: "name",
    placeholder: "optional",
  });
  const pace = h(
    "select",
    { id: "run-pace", name: "config.pace" },
    PACES.map((p) => h("option", { value: p.value }, p.label)),
  );
  const paceCustom = h("input", {
    type: "number",
    id: "run-pace-custom",
    min: "0.01",
    step: "any",
    value: "10",
    hidden: true,
    "aria-label": "Custom pace (real-time multiple)",
  });
  pace.addEventListener("change", () => {
    paceCustom.hidden = pace.value !== "custom";
  });
  const cadence = h(
    "select",
    { id: "run-cadence", name: "config.version_every" },
    h("option", { value: "" }, "Every 10 % of the log"),
    h("option", { value: "seconds" }, "Every N seconds of log"),
    h("option", { value: "samples" }, "Every N samples"),
  );
  const cadenceN = h("input", {
    type: "number",
    id: "run-cadence-n",
    min: "1",
    step: "any",
    value: "10",
    hidden: true,
    "aria-label": "Version cadence N",
  });
  cadence.addEventListener("change", () => {
    cadenceN.hidden = !cadence.value;
  });
  // Only a dataset stored as recorded has a raster to choose (the server refuses it
  // otherwise, on config.raster); renderRaster() shows the field for one.
  const raster = h("input", {
    type: "text",
    id: "run-raster",
    name: "config.raster",
    placeholder: "slowest of the channels read",
    autocomplete: "off",
    "aria-describedby": "run-raster-help",
  });
  const rasterHelp = h("div", { class: "help", id: "run-raster-help" });
  const rasterField = h(
    "div",
    { class: "field", hidden: true, "data-run-raster": "" },
    h("label", { for: "run-raster" }, "Raster"),
    raster,
    rasterHelp,
  );
  const renderRaster = () => {
    const d = view.state.dataset;
    rasterField.hidden = !d?.recorded;
    if (!d?.recorded) return;
    const steps = Object.entries(d.timing ?? {}).map(
      ([name, [, , step]]) => `${name} ${fmt(step * 1000, 3)} ms`,
    );
    rasterHelp.textContent =
      "100Hz, 10ms or channel:NAME; empty: the slowest raster among the channels the run " +
      `reads. This log's channels: ${steps.join(", ")}.`;
  };
  // "Run again…": the reused run's options (setup.js), else the draft of a reload.
  const again = view.fromRun?.config ?? null;
  const gates = gatesEditor(view, again?.gates ?? draft?.gates ?? []);
  if (again) {
    const paceValue = again.pace === undefined || again.pace === null ? "max" : String(again.pace);
    if (PACES.some((p) => p.value === paceValue)) pace.value = paceValue;
    else {
      pace.value = "custom";
      paceCustom.value = paceValue;
    }
    const [unit, n] = Object.entries(again.version_every ?? {})[0] ?? [];
    if (unit === "seconds" || unit === "samples") {
      cadence.value = unit;
      cadenceN.value = String(n);
    }
    paceCustom.hidden = pace.value !== "custom";
    cadenceN.hidden = !cadence.value;
    if (typeof again.raster === "string") raster.value = again.raster;
  }
  if (draft && !again) {
    runName.value = draft.options?.["run-name"] ?? "";
    const restore = [
      [pace, "run-pace"],
      [paceCustom, "run-pace-custom"],
      [cadence, "run-cadence"],
      [cadenceN, "run-cadence-n"],
      [raster, "run-raster"],
    ];
    for (const [el, id] of restore) {
      const v = draft.options?.[id];
      if (typeof v === "string" && v !== "") el.value = v;
    }
    paceCustom.hidden = pace.value !== "custom";
    cadenceN.hidden = !cadence.value;
  }

  const el = h(
    "div",
    {},
    h(
      "div",
      { class: "fields" },
      h("div", { class: "field" }, h("label", { for: "run-name" }, "Run name"), runName),
      h(
        "div",
        { class: "field" },
        h("label", { for: "run-pace" }, "Pace"),
        pace,
        paceCustom,
        h(
          "div",
          { class: "help" },
          "Real-time multiple: replay a recorded cycle slowly enough to watch it adapt.",
        ),
      ),
      h(
        "div",
        { class: "field" },
        h("label", { for: "run-cadence" }, "Keep a map version"),
        cadence,
        cadenceN,
      ),
      rasterField,
    ),
    h("div", { class: "label" }, "Sample gates"),
    h(
      "p",
      { class: "help", style: { marginTop: 0 } },
      "Reject samples outside a range, changing too fast, or shortly after an event.",
    ),
    gates.el,
    gates.addButton,
  );

  const read = () => {
    const out = {};
    if (pace.value === "custom") out.pace = Number(paceCustom.value);
    else if (pace.value !== "max") out.pace = Number(pace.value);
    if (cadence.value) out.version_every = { [cadence.value]: Number(cadenceN.value) };
    const gateList = gates.read();
    if (gateList.length) out.gates = gateList;
    if (!rasterField.hidden && raster.value.trim()) out.raster = raster.value.trim();
    return out;
  };
  return { el, gates, read, renderRaster, name: () => runName.value.trim() };
}
