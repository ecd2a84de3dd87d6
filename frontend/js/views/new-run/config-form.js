/**
 * Section 5: a configuration form per chosen estimator, generated from its schema and
 * defaults, one tab each when several are chosen. A form is kept while its estimator stays
 * chosen on the same dataset, so switching estimators on and off keeps what was typed.
 */
import { SEL } from "../../constants.js";
import { h } from "../../dom.js";
import { rolesOf } from "../../mapping.js";
import { schemaForm } from "../../schema-form.js";
import { restoreControls } from "./draft.js";
import { shortPaper } from "./picker.js";
import { startOf } from "./setup.js";
import { channels, selectedEstimators } from "./state.js";

/** Config properties filled from the signal mapping and the grid editor, not the form. */
const FROM_ELSEWHERE = new Set(["axes", "output", "output_unit", "locked"]);

/** The config keys an estimator's form leaves out: set by the signals and the grid. */
export function hiddenKeys(est) {
  return new Set([
    ...FROM_ELSEWHERE,
    ...rolesOf(est).flatMap((r) => [r.role, `${r.role}_channel`]),
  ]);
}

/**
 * The form of one estimator in its tab panel: the catalog's defaults, overridden by the
 * scenario's setup or a previous run (setup.js), with the draft's values put back once.
 */
function configForm(view, e) {
  const { state, draft } = view;
  const start = startOf(view, e.name);
  const f = schemaForm(e.config_schema ?? {}, {
    defaults: e.defaults ?? {},
    values: start?.config ?? {},
    valuesSource: start?.source ?? "",
    hide: hiddenKeys(e),
    channels: channels(view),
    idPrefix: `cfg-${e.name}`,
  });
  f.datasetId = state.datasetId;
  f.source = start?.source ?? "";
  const paper = e.paper ? shortPaper(e.paper) : "";
  const about = start
    ? `${e.title}. Settings from the ${start.source}; the rest are the defaults ` +
      "(each field says where its default comes from)."
    : `${e.title}${paper ? ` (${paper})` : ""}. Each field says where its default comes from: ` +
      "a paper's value, or a mapwise default where the paper gives none.";
  f.panel = h(
    "div",
    {
      role: "tabpanel",
      id: `panel-${e.name}`,
      "aria-labelledby": `tab-${e.name}`,
      "data-config": e.name,
    },
    h("p", { class: "help", style: { marginTop: 0 } }, about),
    f.el,
  );
  if (draft?.config?.[e.name]) {
    restoreControls(f.panel, draft.config[e.name]);
    delete draft.config[e.name];
  }
  return f;
}

export function renderConfig(view) {
  const { state } = view;
  const host = view.hosts.config;
  const ests = selectedEstimators(view);
  const keep = new Map();
  for (const e of ests) {
    const existing = state.forms.get(e.name);
    const reuse =
      existing &&
      existing.datasetId === state.datasetId &&
      existing.source === (startOf(view, e.name)?.source ?? "");
    keep.set(e.name, reuse ? existing : configForm(view, e));
  }
  state.forms = keep;
  if (!ests.length) {
    host.replaceChildren(h("p", { class: "help" }, "Pick an estimator first."));
    return;
  }
  if (!state.tab || !keep.has(state.tab)) state.tab = ests[0].name;
  const panels = ests.map((e) => {
    const panel = keep.get(e.name).panel;
    panel.hidden = e.name !== state.tab;
    return panel;
  });
  host.replaceChildren(ests.length > 1 ? configTabs(view, ests) : h("div"), ...panels);
  view.updateSubmit();
}

/** The tab list (arrow keys move between tabs). */
function configTabs(view, ests) {
  const { state } = view;
  const onkeydown = (ev) => {
    const i = ests.findIndex((x) => x.name === state.tab);
    if (ev.key === "ArrowRight") selectTab(view, ests[(i + 1) % ests.length].name, true);
    if (ev.key === "ArrowLeft")
      selectTab(view, ests[(i - 1 + ests.length) % ests.length].name, true);
  };
  return h(
    "div",
    { class: "tabs", role: "tablist", "aria-label": "Estimator configuration" },
    ests.map((e) =>
      h(
        "button",
        {
          type: "button",
          role: "tab",
          id: `tab-${e.name}`,
          "aria-controls": `panel-${e.name}`,
          "aria-selected": String(e.name === state.tab),
          tabindex: e.name === state.tab ? "0" : "-1",
          onclick: () => selectTab(view, e.name),
          onkeydown,
        },
        e.name,
      ),
    ),
  );
}

/** Open the tab of estimator `name` (and focus it, from the keyboard). */
export function selectTab(view, name, focus = false) {
  const host = view.hosts.config;
  view.state.tab = name;
  for (const b of host.querySelectorAll(SEL.tab)) {
    const on = b.id === `tab-${name}`;
    b.setAttribute("aria-selected", String(on));
    b.tabIndex = on ? 0 : -1;
    if (on && focus) b.focus();
  }
  for (const p of host.querySelectorAll(SEL.tabPanel)) p.hidden = p.dataset.config !== name;
}
