/**
 * What the Sweeps and Batches views share: a group's progress, sortable table headers whose
 * state lives in the URL (?sort=key:asc). Both poll (poll.js) while any run is queued or running.
 */
import { api } from "./api.js";
import { GROUP_POLL_MS, RUN_ACTIVE, SELECT } from "./constants.js";
import { fill, fmt, fmtDate, h, metricLabel } from "./dom.js";
import { poll } from "./poll.js";

/** Datasets a batch's row of the list names (the rest are counted). */
const LISTED_DATASETS = 4;

/** Runs of a group that are finished, of all, and whether any is still going. */
export function progressOf(group) {
  const runs = group.runs ?? [];
  const done = runs.filter((r) => !RUN_ACTIVE.has(r.status)).length;
  return { done, total: runs.length, active: done < runs.length };
}

/** "4 succeeded · 2 running" as status pills, in a fixed order. */
export function countBadges(counts) {
  const order = ["running", "queued", "succeeded", "failed", "cancelled", "interrupted"];
  const rank = (k) => (order.includes(k) ? order.indexOf(k) : order.length);
  const keys = Object.keys(counts ?? {}).sort((a, b) => rank(a) - rank(b));
  return h(
    "span",
    { class: "row", style: { gap: "6px" }, "data-counts": "" },
    keys.map((k) => h("span", { class: "badge", dataset: { status: k } }, `${counts[k]} ${k}`)),
  );
}

/** A progress bar with its numbers, for the head of a sweep or batch. */
export function progressBar(group, label) {
  const { done, total } = progressOf(group);
  const pct = total ? Math.round((100 * done) / total) : 0;
  return h(
    "div",
    { class: "group-progress", "data-group-progress": "" },
    h(
      "div",
      {
        class: "progress",
        role: "progressbar",
        "aria-label": label,
        "aria-valuemin": "0",
        "aria-valuemax": "100",
        "aria-valuenow": String(pct),
      },
      h("span", { style: { width: `${pct}%` } }),
    ),
    h("span", { class: "pct" }, `${done} of ${total} runs finished`),
    countBadges(group.counts),
  );
}

/* ---------- sortable tables ---------- */

/** "metric:desc" → {key: "metric", dir: -1}; anything else → the fallback. */
export function parseSort(text, fallback = { key: null, dir: 1 }) {
  const m = /^(.+):(asc|desc)$/.exec(text ?? "");
  return m ? { key: m[1], dir: m[2] === "asc" ? 1 : -1 } : { ...fallback };
}

export function formatSort({ key, dir }) {
  return key ? `${key}:${dir > 0 ? "asc" : "desc"}` : undefined;
}

/** Rows sorted by the column `sort.key` (values from column.value); empty values last, ties by input order. */
export function sortRows(rows, columns, sort) {
  const col = columns.find((c) => c.key === sort.key);
  if (!col) return [...rows];
  const value = col.sortValue ?? col.value;
  return rows
    .map((row, i) => ({ row, i, v: value(row) }))
    .sort((a, b) => {
      const ea = a.v === null || a.v === undefined;
      const eb = b.v === null || b.v === undefined;
      if (ea || eb) return ea === eb ? a.i - b.i : ea ? 1 : -1;
      const c =
        typeof a.v === "number" && typeof b.v === "number"
          ? a.v - b.v
          : String(a.v).localeCompare(String(b.v));
      return c * sort.dir || a.i - b.i;
    })
    .map((x) => x.row);
}

/**
 * The header row: one sort button per column (aria-sort on its <th>). onSort(key) is called
 * with the clicked column; the caller re-renders and calls focusSort to keep the focus.
 */
export function sortHeader(columns, sort, onSort) {
  return h(
    "tr",
    {},
    columns.map((c) => {
      const state = sort.key === c.key ? (sort.dir > 0 ? "ascending" : "descending") : "none";
      return h(
        "th",
        {
          scope: "col",
          class: c.num ? "num" : null,
          title: c.title || null,
          "aria-sort": c.sortable === false ? null : state,
        },
        c.sortable === false
          ? c.label
          : h(
              "button",
              { type: "button", class: "sort", "data-sort": c.key, onclick: () => onSort(c.key) },
              c.label,
            ),
      );
    }),
  );
}

/** The next sort after a click on `key`: the same column flips, another starts ascending. */
export function nextSort(sort, key) {
  return { key, dir: sort.key === key ? -sort.dir : 1 };
}

export function focusSort(root, key) {
  root.querySelector(SELECT.sortButton(key))?.focus();
}

/* ---------- list pages ---------- */

/** The table of all sweeps or batches. */
export function groupTable(groups, { kind, datasetName }) {
  if (!groups.length) return null;
  const sweep = kind === "sweep";
  const head = h(
    "tr",
    {},
    [
      sweep ? "Sweep" : "Batch",
      "Estimator",
      sweep ? "Ranked by" : "Datasets",
      "Runs",
      sweep ? "Best run" : "Aggregate",
      "Created",
    ].map((t) => h("th", { scope: "col", class: t === "Best run" ? "num" : null }, t)),
  );
  const rows = groups.map((g) => {
    const { active } = progressOf(g);
    const best = sweep ? g.runs.find((r) => r.id === g.best_run_id) : null;
    const ids = [...new Set(g.runs.map((r) => r.dataset_id))];
    const allOk = g.runs.length > 0 && g.runs.every((r) => r.status === "succeeded");
    return h(
      "tr",
      { dataset: { groupId: g.id } },
      h(
        "td",
        { class: "wrap" },
        h("a", { href: `/${sweep ? "sweeps" : "batches"}/${g.id}` }, g.name),
        " ",
        h("span", { class: "sub" }, `#${g.id}`),
      ),
      h("td", {}, h("code", { class: "tag accent" }, g.estimator)),
      h(
        "td",
        { class: "wrap" },
        sweep
          ? `${metricLabel(g.metric ?? "")} (${g.order === "max" ? "highest" : "lowest"} first)`
          : ids.length > LISTED_DATASETS
            ? `${ids
                .slice(0, LISTED_DATASETS - 1)
                .map(datasetName)
                .join(", ")} and ${ids.length - LISTED_DATASETS + 1} more`
            : ids.map(datasetName).join(", "),
      ),
      h("td", {}, countBadges(g.counts)),
      h(
        "td",
        { class: sweep ? "num" : null },
        sweep
          ? best
            ? [h("a", { href: `/runs/${best.id}` }, `#${best.id}`), ` ${fmt(best.metric)}`]
            : "–"
          : allOk
            ? "ready"
            : active
              ? "once every run has finished"
              : "needs every run to succeed",
      ),
      h("td", {}, fmtDate(g.created_at)),
    );
  });
  return h(
    "div",
    { class: "table-wrap" },
    h(
      "table",
      { class: "data", [`data-${kind}-list`]: "" },
      h("thead", {}, head),
      h("tbody", {}, rows),
    ),
  );
}

/**
 * Shows a sweep or batch now, then re-reads it from `url` while any of its runs is active.
 * A failed read keeps the last state on screen, says so in `progressHost` and tries again
 * (a restarting server, a lost connection).
 */
export async function followGroup(ctx, url, progressHost, show) {
  let first = true;
  let group = null;
  await poll(
    ctx.signal,
    async () => {
      if (!first) {
        try {
          group = await api.get(url, { signal: ctx.signal });
        } catch (err) {
          if (err.name === "AbortError") throw err;
          fill(
            progressHost,
            h(
              "div",
              { class: "banner warn", role: "status" },
              `Refresh failed (${err.message}); trying again.`,
            ),
          );
          return true;
        }
      }
      group = show(first ? null : group);
      first = false;
      return progressOf(group).active;
    },
    GROUP_POLL_MS,
  );
}
