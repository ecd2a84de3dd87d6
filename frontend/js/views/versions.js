/**
 * Versions: pick two map versions (of one run or two), see both on one colour scale and their
 * difference B − A, label either ("release candidate"), export it or keep it as a base map.
 * URL: /versions?a=RUN:N&b=RUN:N, N a version's number 1…n in its run (a=RUN alone: its first
 * and final versions). An old link's RUN:ID (database id) still opens that version when no
 * version has that number; a number the run does not have is said, never silently replaced.
 */
import { api, clearErrors, showError } from "../api.js";
import { EVT, EXPORT_FORMATS } from "../constants.js";
import { card, fmt, fmtInt, h, icon, ICONS, pageHead, toast } from "../dom.js";
import { diffNested, sameGrid } from "../grid-math.js";
import { MapPlot, SliceGroup } from "../map-plot.js";
import { runQuantity } from "../quantity.js";
import { SCOPE } from "../scopes.js";

export const title = "Versions";

export async function mount(root, ctx) {
  const [allRuns, datasets] = await Promise.all([
    api.all("/api/runs", { signal: ctx.signal }),
    api.all("/api/datasets", { signal: ctx.signal }).catch(() => []),
  ]);
  const runs = allRuns.filter((r) => r.produces_map !== false);
  root.append(
    pageHead({
      title: "Versions",
      sub: "Compare two map versions, label the one you trust, and export it.",
    }),
  );
  if (!runs.length) {
    root.append(
      card({
        title: "No maps yet",
        body: h(
          "p",
          {},
          "Versions appear as map runs progress. ",
          h("a", { href: "/runs/new" }, "Start a run →"),
        ),
      }),
    );
    return undefined;
  }

  const parse = (text) => {
    const [r, v] = String(text ?? "").split(":");
    const run = Number(r);
    const version = v === undefined || v === "" ? null : Number(v);
    return {
      run: Number.isInteger(run) && run > 0 ? run : null,
      // version: the number asked for; asked: the text, kept to name what is not there
      version: Number.isInteger(version) && version > 0 ? version : null,
      asked: v === undefined || v === "" ? null : v,
    };
  };
  const a = parse(ctx.query.get("a"));
  const b = parse(ctx.query.get("b"));
  // A run the URL names that is not listed (no such run, or one without a map) is said,
  // never silently replaced by another run.
  for (const [key, side] of [
    ["A", a],
    ["B", b],
  ]) {
    if (side.run === null || runs.some((r) => r.id === side.run)) continue;
    const noMap = allRuns.some((r) => r.id === side.run);
    const asked = side.asked ? `, so there is no version ${side.asked}` : "";
    root.append(
      h(
        "div",
        { class: "banner warn", role: "alert", "data-run-missing": key.toLowerCase() },
        `${key}: run ${side.run} ${noMap ? "produces no map" : "not found"}${asked}. ` +
          "Showing another run instead; pick one below.",
      ),
    );
    Object.assign(side, { run: null, version: null, asked: null });
  }
  if (!a.run)
    a.run = runs.find((r) => r.n_versions > 0 || r.status === "succeeded")?.id ?? runs[0].id;
  if (!b.run) b.run = a.run;

  const sides = { a: { ...a, versions: [], doc: null }, b: { ...b, versions: [], doc: null } };
  const plots = {};
  // A, B and their difference show the same slice of a 3-D table.
  const slices = new SliceGroup();
  const unitOf = (runId) => {
    const r = runs.find((x) => x.id === runId);
    return runQuantity(r, datasets);
  };

  const stats = h("div", { "data-diff-stats": "" });
  const sideCards = {};
  for (const key of ["a", "b"]) sideCards[key] = sideCard(key);
  const diffEl = h("div", {
    class: "plot map",
    "data-plot": "diff",
    role: "img",
    "aria-label": "Difference B minus A",
  });
  plots.diff = new MapPlot(diffEl, { kind: "diff", slices });
  root.append(
    h(
      "div",
      { class: "stack" },
      h("div", { class: "grid cols-2" }, sideCards.a.el, sideCards.b.el),
      card({
        title: "Difference B − A",
        hint: "red: B is higher",
        cls: "version-diff",
        body: h("div", { class: "grid side" }, diffEl, stats),
      }),
    ),
  );

  function sideCard(key) {
    const side = sides[key];
    const runSelect = h(
      "select",
      { id: `run-${key}`, name: `run_${key}`, "aria-label": `Run ${key.toUpperCase()}` },
      runs.map((r) =>
        h(
          "option",
          { value: String(r.id), selected: r.id === side.run },
          `#${r.id} ${r.estimator}${r.name ? ` · ${r.name}` : ""}`,
        ),
      ),
    );
    const versionSelect = h("select", {
      id: `version-${key}`,
      name: `version_${key}`,
      "aria-label": `Version ${key.toUpperCase()}`,
      "data-field": "version",
    });
    const plotEl = h("div", {
      class: "plot small",
      "data-plot": `version-${key}`,
      role: "img",
      "aria-label": `Map version ${key.toUpperCase()}`,
    });
    const info = h("div", { class: "help", "data-version-info": key });
    const missing = h("div", {
      class: "banner warn",
      role: "alert",
      hidden: true,
      "data-version-missing": key,
    });
    const labelInput = h("input", {
      type: "text",
      id: `label-${key}`,
      name: "label",
      placeholder: "e.g. release candidate",
    });
    const format = h(
      "select",
      { id: `format-${key}`, "aria-label": `Export format for ${key.toUpperCase()}` },
      EXPORT_FORMATS.map((f) => h("option", { value: f.value }, f.label)),
    );
    const form = h(
      "form",
      { novalidate: true, "aria-label": `Label version ${key.toUpperCase()}` },
      h(
        "div",
        { class: "field" },
        h("label", { for: `label-${key}` }, "Label"),
        h(
          "div",
          { class: "row", style: { flexWrap: "nowrap" } },
          labelInput,
          h(
            "button",
            { type: "submit", class: "small", "data-save-label": key, "data-needs": SCOPE.run },
            icon(ICONS.tag),
            "Save",
          ),
        ),
      ),
      h("div", { class: "banner error", "data-form-error": "", hidden: true }),
    );
    form.addEventListener("submit", async (e) => {
      e.preventDefault();
      clearErrors(form);
      if (!side.doc) return;
      try {
        const updated = await api.patch(`/api/runs/${side.run}/versions/${side.doc.id}`, {
          label: labelInput.value.trim() || null,
        });
        const v = side.versions.find((x) => x.id === side.doc.id);
        if (v) v.label = updated.label;
        fillVersions(key);
        toast(updated.label ? `Labelled “${updated.label}”.` : "Label removed.");
      } catch (err) {
        showError(form, err);
      }
    });
    const exportBtn = h(
      "button",
      { type: "button", "data-export": key },
      icon(ICONS.download),
      "Export",
    );
    exportBtn.addEventListener("click", async () => {
      try {
        await api.download(
          `/api/runs/${side.run}/export`,
          { format: format.value, version: side.doc?.id },
          `run-${side.run}-v${side.version}.${format.value}`,
        );
      } catch (err) {
        showError(form, err);
      }
    });
    const baseBtn = h(
      "button",
      { type: "button", "data-base-map": key, "data-needs": SCOPE.admin },
      "Save as base map",
    );
    baseBtn.addEventListener("click", async () => {
      try {
        const runName = runs.find((r) => r.id === side.run)?.name || `run ${side.run}`;
        const map = await api.post("/api/base-maps", {
          run_id: side.run,
          version_id: side.doc?.id,
          name: `${runName} v${side.version}${labelInput.value ? ` (${labelInput.value})` : ""}`,
        });
        toast(`Saved base map #${map.id}.`);
      } catch (err) {
        showError(form, err);
      }
    });
    runSelect.addEventListener("change", async () => {
      side.run = Number(runSelect.value);
      side.version = null;
      side.asked = null;
      await loadRun(key);
    });
    versionSelect.addEventListener("change", async () => {
      side.version = Number(versionSelect.value);
      missing.hidden = true;
      await loadVersion(key);
    });
    const { unit, label } = unitOf(side.run);
    plots[key] = new MapPlot(plotEl, { kind: "value", unit, label, slices });
    plots[key].barLabel = label;
    const el = card({
      title: key === "a" ? "Version A" : "Version B",
      cls: `version-side ${key}`,
      body: h(
        "div",
        {},
        h(
          "div",
          { class: "picker" },
          h("div", { class: "field" }, h("label", { for: `run-${key}` }, "Run"), runSelect),
          h(
            "div",
            { class: "field" },
            h("label", { for: `version-${key}` }, "Version"),
            versionSelect,
          ),
        ),
        missing,
        plotEl,
        info,
        form,
      ),
      foot: [h("div", { style: { width: "190px" } }, format), exportBtn, baseBtn],
    });
    return { el, versionSelect, labelInput, info, missing, runSelect };
  }

  function fillVersions(key) {
    const side = sides[key];
    const { versionSelect } = sideCards[key];
    versionSelect.replaceChildren(
      ...side.versions.map((v) =>
        h(
          "option",
          { value: String(v.number), selected: v.number === side.version },
          `v${v.number} · t = ${fmt(v.time_s, 4)} s · step ${fmtInt(v.step)}${v.final ? " · final" : ""}${v.label ? ` · “${v.label}”` : ""}`,
        ),
      ),
    );
  }

  async function loadRun(key) {
    const side = sides[key];
    const body = await api.get(`/api/runs/${side.run}/versions`, { signal: ctx.signal });
    side.versions = Array.isArray(body) ? body : (body.items ?? []);
    resolveAsked(key);
    if (!side.versions.some((v) => v.number === side.version)) {
      side.version = side.versions.length
        ? key === "a"
          ? side.versions[0].number
          : side.versions.at(-1).number
        : null;
    }
    const { unit, label } = unitOf(side.run);
    plots[key].unit = unit;
    plots[key].label = plots[key].barLabel = label;
    plots.diff.unit = unit;
    plots.diff.label = label;
    plots.diff.barLabel = `Δ ${label}`;
    fillVersions(key);
    await loadVersion(key);
  }

  /**
   * The version the URL asked for: its number in the run; else, from an old link, the version
   * with that database id; else the banner says the run has no such version (and the side
   * shows its default, first or final).
   */
  function resolveAsked(key) {
    const side = sides[key];
    const { missing } = sideCards[key];
    const asked = side.asked;
    side.asked = null;
    missing.hidden = true;
    if (asked === null) return;
    if (side.versions.some((v) => v.number === side.version)) return;
    const old = side.versions.find((v) => v.id === side.version);
    if (old) {
      side.version = old.number;
      return;
    }
    const n = side.versions.length;
    const has = n ? `it has v1…v${n}` : "it has no versions yet";
    missing.textContent =
      side.version === null
        ? `“${asked}” is not a version number (${has}).`
        : `Run ${side.run} has no version ${side.version} (${has})` +
          (n ? `; showing v${key === "a" ? 1 : n} instead.` : ".");
    missing.hidden = false;
    side.version = null;
  }

  async function loadVersion(key) {
    const side = sides[key];
    const card = sideCards[key];
    const summary = side.versions.find((v) => v.number === side.version);
    if (!summary) {
      side.doc = null;
      card.info.textContent = "This run has no map versions yet.";
      plots[key].clear();
      syncUrl();
      drawDiff();
      return;
    }
    side.doc = await api.get(`/api/runs/${side.run}/versions/${summary.id}`, {
      signal: ctx.signal,
    });
    card.labelInput.value = side.doc.label ?? "";
    card.info.textContent =
      `run #${side.run} v${side.doc.number} · step ${fmtInt(side.doc.step)} · t = ${fmt(side.doc.time_s, 4)} s` +
      (side.doc.axes
        ? ` · ${side.doc.axes.map((x) => `${x.name} (${x.breakpoints.length})`).join(" × ")}`
        : "");
    syncUrl();
    drawAll();
  }

  function drawAll() {
    const docs = ["a", "b"].map((k) => sides[k].doc).filter(Boolean);
    const flat = docs
      .flatMap((d) => d.values.flat(Infinity))
      .filter((v) => v !== null && Number.isFinite(v));
    const range = flat.length ? [Math.min(...flat), Math.max(...flat)] : null;
    for (const k of ["a", "b"]) {
      if (!sides[k].doc) continue;
      plots[k].setRange(range && range[1] > range[0] ? range : null);
      plots[k].render(sides[k].doc);
    }
    drawDiff();
  }

  function drawDiff() {
    const A = sides.a.doc;
    const B = sides.b.doc;
    if (!A || !B) {
      stats.replaceChildren("Pick two versions.");
      return;
    }
    if (!sameGrid(A.axes, B.axes)) {
      plots.diff.clear();
      stats.replaceChildren(
        h(
          "span",
          { class: "banner warn" },
          "The two versions have different grids; no cell-by-cell difference.",
        ),
      );
      return;
    }
    const d = diffNested(A.values, B.values);
    const flat = d.flat(Infinity).filter((v) => v !== null && Number.isFinite(v));
    plots.diff.render({ axes: A.axes, values: d, variances: null, visits: B.visits });
    const maxAbs = flat.length ? Math.max(...flat.map(Math.abs)) : 0;
    const rms = flat.length ? Math.sqrt(flat.reduce((s, v) => s + v * v, 0) / flat.length) : 0;
    const changed = flat.filter((v) => Math.abs(v) > 1e-9 * Math.max(1, maxAbs)).length;
    const unit = plots.diff.unit ? ` ${plots.diff.unit}` : "";
    const mean = flat.length ? flat.reduce((s, v) => s + v, 0) / flat.length : 0;
    const stat = (label, key, value) => [
      h("dt", {}, label),
      h("dd", {}, h("b", { "data-stat": key }, value)),
    ];
    stats.replaceChildren(
      h(
        "dl",
        { class: "kv" },
        stat(
          "A",
          "a",
          `run #${sides.a.run} v${A.number}, step ${fmtInt(A.step)}${A.label ? ` “${A.label}”` : ""}`,
        ),
        stat(
          "B",
          "b",
          `run #${sides.b.run} v${B.number}, step ${fmtInt(B.step)}${B.label ? ` “${B.label}”` : ""}`,
        ),
        stat("max |Δ|", "max", `${fmt(maxAbs)}${unit}`),
        stat("RMS Δ", "rms", `${fmt(rms)}${unit}`),
        stat("mean Δ", "mean", `${fmt(mean)}${unit}`),
        stat("cells changed", "changed", `${changed} / ${flat.length}`),
      ),
    );
  }

  function syncUrl() {
    const enc = (s) => (s.version ? `${s.run}:${s.version}` : String(s.run));
    ctx.setQuery({ a: enc(sides.a), b: enc(sides.b) });
  }

  try {
    await Promise.all([loadRun("a"), loadRun("b")]);
  } catch (err) {
    if (err.name !== "AbortError") showError(root, err);
  }
  const onTheme = () => drawAll();
  window.addEventListener(EVT.themeChange, onTheme);
  return () => {
    window.removeEventListener(EVT.themeChange, onTheme);
    plots.a?.destroy();
    plots.b?.destroy();
    plots.diff?.destroy();
  };
}
