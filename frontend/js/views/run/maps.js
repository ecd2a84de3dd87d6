/**
 * The run's maps: the table as a heatmap or 3-D surface with the operating-point trail and
 * the active cell, beside its variances (log colour scale) or, for observers without a
 * covariance, the visits per cell; and the versions timeline (slider + play) that shows a
 * stored version instead of the live map.
 */
import { RUN_ACTIVE, SEL, STORAGE } from "../../constants.js";
import { card, flatten, h, icon, ICONS, withUnit } from "../../dom.js";
import { niceRange } from "../../grid-math.js";
import { MapPlot, SliceGroup, squared } from "../../map-plot.js";
import { hasWebGL } from "../../plot.js";
import { VersionTimeline } from "../../timeline.js";
import { trustLegend, trustMaps, trustOverlay } from "./trust-maps.js";

/**
 * The map and variance plots of the run, with a fixed colour range (see runRange).
 * Returns {mapCard, varCard, draw(frame, {variance, map}), destroy()}.
 */
export function runMaps(v, preview) {
  const { outputName, outputUnit } = v;
  const mapMode =
    localStorage.getItem(STORAGE.mapMode) === "surface" && hasWebGL() ? "surface" : "heatmap";
  const axesText = (v.s.axes ?? []).map((a) => a.name).join(" and ");
  const mapEl = h("div", {
    class: "plot map",
    "data-plot": "map",
    role: "img",
    "aria-label": `Map ${withUnit(outputName, outputUnit)} over ${axesText}`,
  });
  const varEl = h("div", {
    class: "plot map",
    "data-plot": "variance",
    role: "img",
    "aria-label": "Cell variances, log colour scale",
  });
  // Live maps skip the cell gaps: cheaper frames (see MapPlot.drawBar for the colour bar).
  const slices = new SliceGroup();
  const common = { unit: outputUnit, label: outputName, gaps: false, slices };
  const mapPlot = new MapPlot(mapEl, { kind: "value", mode: mapMode, ...common });
  const varPlot = new MapPlot(varEl, { kind: "variance", ...common });
  mapPlot.setRange(runRange(v.run, preview));
  // Trust (trust-maps.js): unvisited and filled cells over the map, hits and error maps.
  mapPlot.overlay = trustOverlay;
  mapPlot.barLabel = outputName;
  const trust = trustMaps(v, { slices });
  const modeButtons = ["heatmap", "surface"].map((m) =>
    h(
      "button",
      {
        type: "button",
        "aria-pressed": String(m === mapMode),
        "data-map-mode": m,
        disabled: m === "surface" && !hasWebGL(),
        title: m === "surface" && !hasWebGL() ? "3-D needs WebGL, which this browser lacks" : null,
        onclick: () => {
          mapPlot.setMode(m);
          localStorage.setItem(STORAGE.mapMode, m);
          for (const b of modeButtons)
            b.setAttribute("aria-pressed", String(b.dataset.mapMode === m));
        },
      },
      m === "heatmap" ? icon(ICONS.grid) : icon(ICONS.cube),
      m === "heatmap" ? "Heatmap" : "3-D",
    ),
  );
  const varCard = card({
    title: "Variance",
    hint: `diag P [${squared(outputUnit || "-")}], log colour scale`,
    body: varEl,
    bodyCls: "tight",
  });
  const mapActions = (note) => [
    note,
    h("div", { class: "seg", role: "group", "aria-label": "Map display" }, modeButtons),
  ];

  function draw(rawFrame, { variance = true, map = true } = {}) {
    if (!v.producesMap || !rawFrame.axes || !rawFrame.values) return;
    const frame = { ...rawFrame, cellState: trust.states(rawFrame) };
    self.lastFrame = frame;
    if (map) mapPlot.render(frame);
    if (!variance) return;
    trust.draw(frame);
    // Observers without a covariance show the hits in the second map already (below).
    trust.hitsCard.hidden = Boolean(frame.visits && !frame.variances);
    if (frame.variances) varPlot.render(frame);
    else if (frame.visits) {
      // Observers without a covariance (LPV): the second map shows where the log has been.
      if (varPlot.kind !== "visits") {
        varPlot.kind = "visits";
        varPlot.range = null;
        varEl.setAttribute("aria-label", "Visits per cell");
        varCard
          .querySelector(SEL.cardTitle)
          .replaceChildren(
            "Visits",
            h("span", { class: "hint" }, " · samples weighted onto each cell (no covariance)"),
          );
      }
      varPlot.render(frame);
    }
  }

  const self = {
    /** The map card, its actions: the timeline's "viewing version" note and the mode switch. */
    mapCard: (note) =>
      card({
        title: "Map",
        hint: withUnit(outputName, outputUnit || "-"),
        actions: mapActions(note),
        body: [mapEl, trustLegend()],
        bodyCls: "tight",
      }),
    varCard,
    /** The hits per cell and, on a simulated dataset, the error against the truth. */
    hitsCard: trust.hitsCard,
    errorCard: trust.errorCard,
    loadTruth: trust.loadTruth,
    lastFrame: null,
    draw,
    destroy: () => {
      mapPlot.destroy();
      varPlot.destroy();
      trust.destroy();
    },
  };
  return self;
}

/**
 * The versions timeline: scrubbing shows a stored version (in the URL as ?version=N, N its
 * number 1…n in the run; an old link's ?version_id=ID still opens it), "live" returns to the
 * stream; the list of versions updates the metric cards and Versions link.
 */
export function runTimeline(v) {
  const { id, ctx, s } = v;
  return new VersionTimeline({
    runId: id,
    initialVersion: ctx.query.get("version"),
    initialVersionId: ctx.query.get("version_id"),
    onScrub: (version) => ctx.setQuery({ version: version?.number }),
    isLive: () => RUN_ACTIVE.has(s.run.status),
    onShow: (doc, _version, { quiet }) =>
      v.maps.draw({
        axes: doc.axes ?? s.axes,
        values: doc.values,
        variances: doc.variances,
        visits: doc.visits,
        cellRejections: doc.cell_rejections ?? null,
        trail: quiet ? s.trail : null,
        activeCell: null,
      }),
    onLive: () => {
      s.dirtyMap = true;
    },
    onList: (versions) => {
      v.meta.linkVersions(versions);
      v.meta.renderMetrics();
    },
    baseMapName: () => s.run.name || `run ${id}`,
  });
}

/**
 * The run's colour range: the measured output's span over the whole log together with the
 * starting map (θ0, typed values or a base map), on nice bounds; null when there is no
 * measured output (the plot then seeds from its first frame). Cells the filter extrapolates
 * beyond it saturate at the ends of the scale rather than rescale every frame.
 */
function runRange(run, preview) {
  const values = preview?.channels?.[run.signals?.y]?.values ?? [];
  const start = flatten([run.estimator_config?.theta0 ?? run.config?.theta0 ?? []]);
  let lo = Infinity;
  let hi = -Infinity;
  for (const x of [...values, ...start]) {
    if (typeof x !== "number" || !Number.isFinite(x)) continue;
    if (x < lo) lo = x;
    if (x > hi) hi = x;
  }
  return values.length && hi >= lo ? niceRange(lo, hi) : null;
}
