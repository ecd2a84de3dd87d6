/**
 * The render loop: stream messages only mark what changed; each animation frame draws at
 * most one thing, the map first (20 frames/s), its variances at most every 100 ms, the series
 * every 250 ms and the progress and cards every 400 ms, so a long series redraw never delays
 * a map frame.
 */
import { FRAME_INTERVAL_MS } from "../../constants.js";
import { liveFrame } from "./state.js";

const SERIES_INTERVAL_MS = 250;
/** requestAnimationFrame ticks every ~16.7 ms: a frame due in under this much is drawn now, so
 * 20 frames/s are not rounded down to 15 by a tick that lands a hair early. */
const FRAME_SLACK_MS = 6;
const VARIANCE_INTERVAL_MS = 100;
const META_INTERVAL_MS = 400;

/** Start drawing `v.s` as it changes; returns the function that stops. */
export function startRenderLoop(v) {
  const { s } = v;
  // A stored version on show (the timeline) replaces the live maps until "live" again.
  const live = () => !v.timeline.viewing;

  function drawOne(now) {
    if (s.dirtyMap && now - s.lastMap >= FRAME_INTERVAL_MS - FRAME_SLACK_MS) {
      s.lastMap = now;
      s.dirtyMap = false;
      const withVariance = now - s.lastVariance >= VARIANCE_INTERVAL_MS;
      if (withVariance) s.lastVariance = now;
      else s.dirtyVariance = true;
      if (live()) v.maps.draw(liveFrame(s), { variance: withVariance });
      return;
    }
    if (s.dirtyVariance && now - s.lastVariance >= VARIANCE_INTERVAL_MS && live()) {
      s.lastVariance = now;
      s.dirtyVariance = false;
      if (s.axes && s.values) v.maps.draw(liveFrame(s), { map: false });
      return;
    }
    if (s.dirtySeries && now - s.lastSeries >= SERIES_INTERVAL_MS) {
      s.lastSeries = now;
      s.dirtySeries = false;
      v.series.draw();
      return;
    }
    if (s.dirtyMeta && now - s.lastMeta >= META_INTERVAL_MS) {
      s.lastMeta = now;
      s.dirtyMeta = false;
      v.meta.renderProgress();
      v.meta.renderMetrics();
      v.meta.renderGates();
    }
  }

  let raf = 0;
  const loop = (now) => {
    raf = requestAnimationFrame(loop);
    drawOne(now);
  };
  raf = requestAnimationFrame(loop);
  return () => cancelAnimationFrame(raf);
}
