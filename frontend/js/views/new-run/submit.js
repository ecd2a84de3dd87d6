/**
 * Starting what the form describes. Every part is checked before the first POST, so all
 * problems show at once, each next to its field (a config problem marks its estimator's tab).
 * Several estimators start one run each, then open their comparison (of those the API
 * accepted, when it refuses one); a sweep or batch is one POST, then its page.
 */
import { api, clearErrors, showError } from "../../api.js";
import { SEL, SELECT } from "../../constants.js";
import { toast } from "../../dom.js";
import { needsTable, rolesOf } from "../../mapping.js";
import { readBatch } from "./batch-form.js";
import { calibrationOf } from "./ecu-prefill.js";
import { fieldError, selectedEstimators } from "./state.js";
import { dropKey, readSweep } from "./sweep-request.js";

/** The POST /api/runs body of one estimator; `shared` holds the options and grid of all. */
function bodyFor(view, est, shared) {
  const { state } = view;
  const config = { ...state.forms.get(est.name).read(), ...shared.options };
  const signals = {};
  for (const r of rolesOf(est)) if (state.signals[r.role]) signals[r.role] = state.signals[r.role];
  if (est.kind === "table-filter" && state.signals.y) signals.y = state.signals.y;
  const body = { dataset_id: state.datasetId, estimator: est.name, signals, config };
  if (needsTable(est) && shared.grid) {
    body.table = shared.grid.table;
    if (shared.grid.base_map_id) body.base_map_id = shared.grid.base_map_id;
    if (shared.grid.locked) config.locked = shared.grid.locked;
    // Typed or imported start values replace the constant θ0 (the API keeps an explicit θ0).
    if (body.table.values || body.base_map_id) delete config.theta0;
    // A map from an ECU's A2L: the run keeps the link its CDFX and image exports need.
    const calibration = calibrationOf(view);
    if (calibration) body.calibration = calibration;
  }
  const name = view.options.name();
  if (name) body.name = selectedEstimators(view).length > 1 ? `${name} · ${est.name}` : name;
  return body;
}

/** The form's submit handler. */
export async function submitForm(view, e) {
  e.preventDefault();
  clearErrors(view.form);
  for (const b of view.hosts.config.querySelectorAll(SEL.tab)) b.removeAttribute("data-invalid");
  const ests = selectedEstimators(view);
  if (!ests.length) {
    showError(view.form, { message: "Pick at least one estimator.", field: "estimator" });
    return;
  }
  if (view.state.mode !== "single") await submitGroup(view, ests[0]);
  else await submitRuns(view, ests);
}

/** One run per estimator; on to the run, or to the comparison of several. */
async function submitRuns(view, ests) {
  const { state, ctx, submit } = view;
  const problems = [];
  let shared = null;
  try {
    shared = {
      options: view.options.read(),
      grid: ests.some(needsTable) ? state.grid?.read() : null,
    };
  } catch (err) {
    problems.push({ err, estimator: null });
  }
  const bodies = [];
  for (const est of ests) {
    try {
      if (shared) bodies.push(bodyFor(view, est, shared));
      else state.forms.get(est.name).read();
    } catch (err) {
      problems.push({ err, estimator: est.name });
    }
  }
  if (problems.length) {
    reportErrors(view, problems);
    return;
  }
  submit.disabled = true;
  const created = [];
  const failed = [];
  for (const body of bodies) {
    try {
      created.push({ run: await api.post("/api/runs", body), estimator: body.estimator });
    } catch (err) {
      if (err.name === "AbortError") return;
      failed.push({ err, estimator: body.estimator });
    }
  }
  submit.disabled = false;
  if (!created.length) {
    reportErrors(view, failed);
    return;
  }
  view.drafts.forget();
  const compare = `/compare?runs=${created.map((c) => c.run.id).join(",")}`;
  if (failed.length) {
    // Some runs exist already: say which, and show those; the refusals travel in a toast.
    const started = created.map((c) => `#${c.run.id} ${c.estimator}`).join(", ");
    const refused = failed.map((f) => `${f.estimator}: ${f.err.message}`).join("; ");
    toast(`Started ${started}. Not started — ${refused}`, { error: true, ms: 15000 });
    ctx.navigate(compare);
    return;
  }
  ctx.navigate(created.length === 1 ? `/runs/${created[0].run.id}` : compare);
}

/** Start a sweep or a batch: every part checked first, then one POST; on to its page. */
async function submitGroup(view, est) {
  const { state, submit } = view;
  const problems = [];
  let body = null;
  let extra = null;
  try {
    const grid = needsTable(est) ? state.grid?.read() : null;
    body = bodyFor(view, est, { options: view.options.read(), grid });
  } catch (err) {
    problems.push({ err, estimator: est.name });
  }
  if (body?.base_map_id) {
    const message =
      "Sweeps and batches start from a constant θ0 or typed start values, not a base map.";
    problems.push({ err: fieldError("base_map_id", message), estimator: null });
  }
  try {
    extra = state.mode === "sweep" ? readSweep(state.sweep, est) : readBatch(view);
  } catch (err) {
    problems.push({ err, estimator: null });
  }
  if (problems.length) {
    reportErrors(view, problems);
    return;
  }
  // Sweeps and batches keep no calibration link (their runs export DCM, CSV, JSON).
  const { base_map_id: _base, calibration: _cal, dataset_id: datasetId, ...common } = body;
  let path;
  let payload;
  if (state.mode === "sweep") {
    // A swept setting comes from its parameter, not the fixed configuration.
    for (const key of Object.keys(extra.parameters)) dropKey(common.config, key);
    path = "/api/sweeps";
    payload = { dataset_id: datasetId, ...common, ...extra };
  } else {
    path = "/api/batches";
    payload = { dataset_ids: extra, ...common };
  }
  submit.disabled = true;
  let group;
  try {
    group = await api.post(path, payload);
  } catch (err) {
    submit.disabled = false;
    if (err.name === "AbortError") return;
    reportErrors(view, [{ err, estimator: est.name }]);
    return;
  }
  submit.disabled = false;
  view.drafts.forget();
  view.ctx.navigate(`/${state.mode === "sweep" ? "sweeps" : "batches"}/${group.id}`);
}

/**
 * Show every problem next to its field. Estimators with a config problem get their tab marked;
 * the open tab stays open if it has one, else the first such tab opens.
 */
function reportErrors(view, problems) {
  const { state } = view;
  const several = selectedEstimators(view).length > 1;
  let firstTab = null;
  for (const { err, estimator } of problems) {
    const field = err.field ?? "";
    const inConfig =
      field.startsWith("config") && !/^config\.(pace|version_every|gates|raster)/.test(field);
    if (inConfig && estimator && state.forms.has(estimator)) {
      if (firstTab === null || estimator === state.tab) firstTab = estimator;
      view.hosts.config
        .querySelector(SELECT.id(`tab-${estimator}`))
        ?.setAttribute("data-invalid", "");
      showError(state.forms.get(estimator).panel, err);
    } else {
      const named = estimator && several;
      showError(
        view.form,
        named ? Object.assign(err, { message: `${estimator}: ${err.message}` }) : err,
      );
    }
  }
  if (firstTab) {
    view.selectTab(firstTab);
    state.forms.get(firstTab).panel.querySelector(SEL.invalid)?.focus();
  }
}
