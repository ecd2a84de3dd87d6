/**
 * The runs list of the Runs & compare view: paged by the server (GET /api/runs?top_level=true),
 * filtered by name, estimator, dataset and status, with a sweep's or batch's runs grouped under
 * one row that expands to them (GET /api/runs?group=ID). Each run can be picked for comparison,
 * renamed in place (PATCH), cloned (POST …/clone) or deleted with its versions (DELETE, after a
 * confirmation that says how many versions go with it).
 */
import { api } from "../api.js";
import { RUN_ACTIVE } from "../constants.js";
import {
  card,
  confirmDialog,
  debounce,
  fmt,
  fmtDate,
  h,
  icon,
  ICONS,
  metricLabel,
  statusBadge,
  toast,
} from "../dom.js";
import { metricUnit } from "../metric-names.js";
import { runQuantity } from "../quantity.js";
import { SCOPE } from "../scopes.js";

export const PAGE_SIZES = [10, 25, 50, 100];
const DEFAULT_PAGE_SIZE = 25;
const STATUSES = ["queued", "running", "succeeded", "failed", "cancelled", "interrupted"];
const KEY_METRICS = ["ise", "output_rmse", "rmse", "mae"];
const COLUMNS = ["Run", "Estimator", "Dataset", "Status", "Key metric", "Versions", "Created"];
const GROUP_LABEL = { sweep: "Sweep", batch: "Batch" };
const SEARCH_DELAY_MS = 250;
/** Icons of the row actions (the shared set has no pencil or copy). */
const PENCIL = ["M4 20h4L19 9l-4-4L4 16z", "M13.5 6.5l4 4"];
const COPY = ["M9 9h11v11H9z", "M15 9V4H4v11h5"];

/** "3 map versions" / "1 map version" / "no map versions". */
export function versionsPhrase(n) {
  if (!n) return "no map versions";
  return `${n} map version${n === 1 ? "" : "s"}`;
}

/** "Showing 26–50 of 73" for a page of the list. */
export function rangeText(offset, count, total) {
  if (!total) return "Nothing to show";
  return `Showing ${offset + 1}–${offset + count} of ${total}`;
}

/**
 * The "All runs" card. `selectedIds`: runs ticked for comparison at mount; `datasets` and
 * `catalog` name datasets and estimators; `ctx` the view's router context.
 */
export function runsListCard({ selectedIds, datasets, catalog, ctx }) {
  const selected = new Set(selectedIds);
  const expanded = new Set();
  const state = { offset: 0, limit: DEFAULT_PAGE_SIZE, total: 0, seq: 0 };
  const datasetName = (id) => datasets.find((d) => d.id === id)?.name ?? `#${id}`;

  const q = h("input", {
    type: "search",
    id: "runs-q",
    placeholder: "Name contains…",
    "aria-label": "Filter by name",
    autocomplete: "off",
  });
  const estimator = h(
    "select",
    { id: "runs-estimator", "aria-label": "Filter by estimator" },
    h("option", { value: "" }, "All estimators"),
    catalog.map((e) => h("option", { value: e.name }, e.name)),
  );
  const dataset = h(
    "select",
    { id: "runs-dataset", "aria-label": "Filter by dataset" },
    h("option", { value: "" }, "All datasets"),
    datasets.map((d) => h("option", { value: String(d.id) }, d.name)),
  );
  const status = h(
    "select",
    { id: "runs-status", "aria-label": "Filter by status" },
    h("option", { value: "" }, "Any status"),
    STATUSES.map((s) => h("option", { value: s }, s)),
  );
  const pageSize = h(
    "select",
    { id: "runs-page-size", "aria-label": "Entries per page" },
    PAGE_SIZES.map((n) =>
      h("option", { value: String(n), selected: n === DEFAULT_PAGE_SIZE }, `${n} per page`),
    ),
  );
  const compareButton = h(
    "button",
    { type: "button", class: "primary", "data-compare-selected": "" },
    icon(ICONS.compare),
    "Compare selected",
  );
  const prev = h("button", { type: "button", class: "small", "data-page-prev": "" }, "‹ Previous");
  const next = h("button", { type: "button", class: "small", "data-page-next": "" }, "Next ›");
  const range = h("span", { class: "sub", "data-page-range": "", "aria-live": "polite" });
  const errors = h("div", { "data-runs-errors": "" });
  const tbody = h("tbody");
  const table = h(
    "table",
    { class: "data", "data-runs-table": "" },
    h(
      "thead",
      {},
      h(
        "tr",
        {},
        h("th", { scope: "col" }, h("span", { class: "visually-hidden" }, "Select")),
        ...COLUMNS.map((t) =>
          h(
            "th",
            { scope: "col", class: ["Key metric", "Versions"].includes(t) ? "num" : null },
            t,
          ),
        ),
        h("th", { scope: "col" }, h("span", { class: "visually-hidden" }, "Actions")),
      ),
    ),
    tbody,
  );

  /** A banner above the table naming what failed (the server's message names the field). */
  function fail(err, what = "") {
    if (err?.name === "AbortError") return;
    errors.replaceChildren(
      h("div", { class: "banner error", role: "alert" }, `${what}${err?.message ?? err}`),
    );
  }

  function filters() {
    return {
      q: q.value.trim() || undefined,
      estimator: estimator.value || undefined,
      dataset_id: dataset.value || undefined,
      status: status.value || undefined,
    };
  }

  function countSelected() {
    compareButton.disabled = selected.size < 1;
    compareButton.replaceChildren(
      icon(ICONS.compare),
      selected.size > 1 ? `Compare ${selected.size} runs` : "Compare selected",
    );
  }

  /** Fetch and draw the current page (a later call wins over an earlier one still loading). */
  async function load() {
    const seq = ++state.seq;
    let page;
    try {
      page = await api.get("/api/runs", {
        query: { ...filters(), top_level: "true", limit: state.limit, offset: state.offset },
        signal: ctx.signal,
      });
    } catch (err) {
      fail(err);
      return;
    }
    if (seq !== state.seq) return;
    errors.replaceChildren();
    if (!page.items.length && state.offset > 0 && page.total > 0) {
      // The page emptied (its last runs deleted): show the last page that has entries.
      state.offset = Math.max(0, Math.floor((page.total - 1) / state.limit) * state.limit);
      return load();
    }
    state.total = page.total;
    const rows = [];
    for (const r of page.items) {
      if (r.group) {
        rows.push(groupRow(r.group));
        if (expanded.has(r.group.id)) rows.push(...(await childRows(r.group)));
        if (seq !== state.seq) return;
      } else rows.push(runRow(r));
    }
    tbody.replaceChildren(
      ...(rows.length
        ? rows
        : [
            h(
              "tr",
              {},
              h(
                "td",
                { colspan: String(COLUMNS.length + 2), class: "empty", "data-runs-empty": "" },
                Object.values(filters()).some(Boolean)
                  ? "No run matches these filters."
                  : "No runs yet.",
              ),
            ),
          ]),
    );
    range.textContent = rangeText(state.offset, page.items.length, page.total);
    prev.disabled = state.offset === 0;
    next.disabled = state.offset + state.limit >= page.total;
  }

  async function childRows(group) {
    try {
      const runs = await api.all("/api/runs", {
        query: { ...filters(), group: group.id },
        signal: ctx.signal,
      });
      return runs.map((r) => runRow(r, { child: true }));
    } catch (err) {
      fail(err);
      return [];
    }
  }

  function groupRow(group) {
    const open = expanded.has(group.id);
    const kind = GROUP_LABEL[group.kind] ?? group.kind;
    const toggle = h(
      "button",
      {
        type: "button",
        class: "ghost small",
        "aria-expanded": String(open),
        "aria-label": `${open ? "Collapse" : "Expand"} ${kind.toLowerCase()} ${group.name}`,
        "data-group-toggle": group.id,
        onclick: () => {
          if (open) expanded.delete(group.id);
          else expanded.add(group.id);
          load();
        },
      },
      h(
        "span",
        {
          "aria-hidden": "true",
          style: { display: "inline-block", transform: open ? "none" : "rotate(-90deg)" },
        },
        icon(ICONS.chevron),
      ),
    );
    return h(
      "tr",
      { dataset: { groupId: group.id, groupKind: group.kind }, class: "group-row" },
      h("td", {}, toggle),
      h(
        "td",
        { class: "wrap", colspan: String(COLUMNS.length + 1) },
        h("span", { class: "tag" }, kind),
        " ",
        h(
          "a",
          { href: `/${group.kind === "batch" ? "batches" : "sweeps"}/${group.id}` },
          group.name,
        ),
        " ",
        h(
          "span",
          { class: "sub", "data-group-size": "" },
          `· ${group.size} run${group.size === 1 ? "" : "s"}`,
        ),
      ),
    );
  }

  function runRow(r, { child = false } = {}) {
    const est = catalog.find((e) => e.name === r.estimator);
    const box = h("input", {
      type: "checkbox",
      id: `pick-${r.id}`,
      checked: selected.has(r.id),
      "aria-label": `Select run ${r.id}`,
      onchange: (e) => {
        if (e.target.checked) selected.add(r.id);
        else selected.delete(r.id);
        countSelected();
      },
    });
    const keyMetric = Object.entries(r.metrics ?? {}).find(([k]) => KEY_METRICS.includes(k));
    const name = h("span", { class: "sub", "data-run-name": "" }, r.name ?? "");
    const nameCell = h(
      "td",
      { class: "wrap", style: child ? { paddingLeft: "28px" } : null },
      h("a", { href: `/runs/${r.id}` }, `#${r.id}`),
      " ",
      name,
    );
    const active = RUN_ACTIVE.has(r.status);
    const actions = h(
      "td",
      {},
      h(
        "div",
        { class: "row", style: { gap: "2px", flexWrap: "nowrap" } },
        h(
          "button",
          {
            type: "button",
            class: "small ghost icon",
            "data-rename": r.id,
            "data-needs": SCOPE.run,
            "aria-label": `Rename run ${r.id}`,
            title: "Rename",
            onclick: () => startRename(r, nameCell, name),
          },
          icon(PENCIL),
        ),
        h(
          "button",
          {
            type: "button",
            class: "small ghost icon",
            "data-clone": r.id,
            "data-needs": SCOPE.run,
            "aria-label": `Clone run ${r.id}`,
            title: "Clone: queue a copy with the same data and config",
            onclick: () => cloneRun(r),
          },
          icon(COPY),
        ),
        h(
          "button",
          {
            type: "button",
            class: "small ghost danger icon",
            "data-delete": r.id,
            "data-needs": SCOPE.admin,
            "aria-label": `Delete run ${r.id}`,
            title: active ? `Run ${r.id} is ${r.status}: cancel it first` : "Delete",
            disabled: active,
            onclick: () => deleteRun(r),
          },
          icon(ICONS.trash),
        ),
      ),
    );
    return h(
      "tr",
      { dataset: child ? { runId: r.id, parentGroup: r.group_id } : { runId: r.id } },
      h("td", {}, box),
      nameCell,
      h("td", {}, h("code", { class: "tag accent", title: est?.title ?? null }, r.estimator)),
      h("td", {}, datasetName(r.dataset_id)),
      h("td", {}, statusBadge(r.status)),
      h("td", { class: "num" }, keyMetric ? keyMetricText(keyMetric, r, est, datasets) : "–"),
      h("td", { class: "num", "data-run-versions": "" }, String(r.n_versions ?? 0)),
      h("td", {}, fmtDate(r.created_at)),
      actions,
    );
  }

  /** Swap the name for an input: Enter or Save renames, Escape or Cancel restores. */
  function startRename(r, cell, nameEl) {
    if (cell.querySelector("[data-rename-input]")) return;
    const input = h("input", {
      type: "text",
      value: r.name ?? "",
      maxlength: "200",
      "aria-label": `New name of run ${r.id}`,
      "data-rename-input": r.id,
      style: { minWidth: "14em" },
    });
    const problem = h("div", { class: "field-error", role: "alert", "data-rename-error": "" });
    const restore = () => editor.replaceWith(nameEl);
    const save = async () => {
      try {
        const updated = await api.patch(`/api/runs/${r.id}`, { name: input.value });
        r.name = updated.name;
        nameEl.textContent = updated.name;
        restore();
        toast(`Renamed run ${r.id} to “${updated.name}”.`);
      } catch (err) {
        problem.textContent = err.message;
        input.setAttribute("aria-invalid", "true");
      }
    };
    input.addEventListener("keydown", (e) => {
      if (e.key === "Enter") {
        e.preventDefault();
        save();
      } else if (e.key === "Escape") restore();
    });
    const editor = h(
      "span",
      { class: "row", style: { gap: "4px", display: "inline-flex" } },
      input,
      h("button", { type: "button", class: "small primary", onclick: save }, "Save"),
      h("button", { type: "button", class: "small", onclick: restore }, "Cancel"),
      problem,
    );
    nameEl.replaceWith(editor);
    input.focus();
    input.select();
  }

  async function cloneRun(r) {
    try {
      const copy = await api.post(`/api/runs/${r.id}/clone`, {});
      toast(`Queued run ${copy.id}, “${copy.name}”.`);
      state.offset = 0; // the copy is the newest run: first on the first page
      await load();
    } catch (err) {
      fail(err, `Clone of run ${r.id}: `);
    }
  }

  async function deleteRun(r) {
    const ok = await confirmDialog(
      `Delete run ${r.id}, “${r.name}”, with its ${versionsPhrase(r.n_versions)}, its metrics ` +
        "and its series? Base maps saved from it stay. This cannot be undone.",
      { title: "Delete run", confirmLabel: "Delete run", danger: true },
    );
    if (!ok) return;
    try {
      await api.del(`/api/runs/${r.id}`);
    } catch (err) {
      return fail(err, `Run ${r.id}: `);
    }
    selected.delete(r.id);
    countSelected();
    toast(`Deleted run ${r.id}.`);
    await load();
  }

  const refilter = () => {
    state.offset = 0;
    load();
  };
  q.addEventListener("input", debounce(refilter, SEARCH_DELAY_MS));
  for (const el of [estimator, dataset, status]) el.addEventListener("change", refilter);
  pageSize.addEventListener("change", () => {
    state.limit = Number(pageSize.value);
    refilter();
  });
  prev.addEventListener("click", () => {
    state.offset = Math.max(0, state.offset - state.limit);
    load();
  });
  next.addEventListener("click", () => {
    state.offset += state.limit;
    load();
  });
  compareButton.addEventListener("click", () =>
    ctx.navigate(`/compare?runs=${[...selected].sort((a, b) => a - b).join(",")}`),
  );
  countSelected();
  const loaded = load();

  const element = card({
    title: "All runs",
    actions: [compareButton],
    bodyCls: "flush",
    body: h(
      "div",
      {},
      h(
        "div",
        {
          class: "row",
          role: "search",
          "aria-label": "Filter runs",
          style: { gap: "8px", padding: "12px 16px", flexWrap: "wrap" },
        },
        h("div", { style: { width: "220px" } }, q),
        h("div", { style: { width: "180px" } }, estimator),
        h("div", { style: { width: "200px" } }, dataset),
        h("div", { style: { width: "150px" } }, status),
      ),
      errors,
      h("div", { class: "table-wrap" }, table),
    ),
    foot: h(
      "div",
      { class: "row", style: { gap: "8px", justifyContent: "space-between", flexWrap: "wrap" } },
      range,
      h(
        "div",
        { class: "row", style: { gap: "8px" } },
        h("div", { style: { width: "140px" } }, pageSize),
        prev,
        next,
      ),
    ),
  });
  return { element, loaded, reload: load };
}

/** "Output RMSE 2.948 ppm", "ISE 2,669 N²·m²·s": the run's key metric with its unit. */
function keyMetricText([key, value], run, est, datasets) {
  const torque = est?.kind === "torque";
  const unit = metricUnit(key, torque ? "N·m" : runQuantity(run, datasets).unit, { torque });
  return `${metricLabel(key)} ${fmt(value)}${unit && unit !== "-" ? ` ${unit}` : ""}`;
}
