/**
 * The "Export" menu button of a run: one item per format, keyboard operable (menu pattern).
 * A run adapted from an ECU map (its `calibration` link) also exports CDFX and the ECU's
 * memory image with the map patched in (docs/calibration.md#dashboard). A run without a map
 * (a torque observer) offers only what it has: its time series as CSV and MCAP.
 */
import { api, showError } from "./api.js";
import { EXPORT_FORMATS, SEL } from "./constants.js";
import { h, icon, ICONS } from "./dom.js";

/** The formats only a run linked to an ECU map has (`ext`: the file name without a header). */
export const CALIBRATION_FORMATS = Object.freeze([
  { value: "cdfx", label: "CDFX (ASAM CDF 2.0)", ext: "cdfx" },
  { value: "image", label: "Patched ECU image (HEX/S19)", ext: "hex" },
]);

/** The formats of a run's time series (the server's `part=series`), for runs without a map. */
export const SERIES_FORMATS = Object.freeze([
  { value: "csv", label: "CSV time series", ext: "csv" },
  { value: "mcap", label: "MCAP (Foxglove)", ext: "mcap" },
]);

/** The formats a run can export: map formats only if it makes a map. */
export function formatsFor({ producesMap = true, calibration = null } = {}) {
  if (!producesMap) return SERIES_FORMATS;
  return calibration ? [...EXPORT_FORMATS, ...CALIBRATION_FORMATS] : EXPORT_FORMATS;
}

/**
 * @param {number} runId
 * @param {{versionId: () => number|null, errorHost: HTMLElement, signal: AbortSignal,
 *   calibration?: {ecu_id: number, map: string}|null, producesMap?: boolean}} opts
 *   versionId: the version to export (null: the run's final map); calibration: the run's link;
 *   producesMap: false for a run with no map (only its series export)
 */
export function exportMenu(
  runId,
  { versionId, errorHost, signal, calibration = null, producesMap = true },
) {
  const formats = formatsFor({ producesMap, calibration });
  const list = h(
    "div",
    { class: "menu-list", role: "menu", hidden: true },
    formats.map((f) =>
      h(
        "button",
        {
          type: "button",
          role: "menuitem",
          tabindex: "-1",
          "data-export": f.value,
          onclick: async () => {
            close();
            const vid = producesMap ? versionId() : null;
            try {
              await api.download(
                `/api/runs/${runId}/export`,
                producesMap
                  ? { format: f.value, version: vid ?? undefined }
                  : { format: f.value, part: f.value === "csv" ? "series" : undefined },
                `run-${runId}.${f.ext ?? f.value}`,
              );
            } catch (err) {
              showError(errorHost, err);
            }
          },
        },
        f.label,
      ),
    ),
  );
  const button = h(
    "button",
    { type: "button", "aria-haspopup": "menu", "aria-expanded": "false", "data-export-menu": "" },
    icon(ICONS.download),
    "Export",
    icon(ICONS.chevron),
  );
  const el = h("div", { class: "menu" }, button, list);

  function open() {
    list.hidden = false;
    button.setAttribute("aria-expanded", "true");
    list.querySelector(SEL.menuItem)?.focus();
  }

  function close() {
    list.hidden = true;
    button.setAttribute("aria-expanded", "false");
  }

  button.addEventListener("click", () => (list.hidden ? open() : close()));
  list.addEventListener("keydown", (e) => {
    const items = [...list.querySelectorAll(SEL.menuItem)];
    const i = items.indexOf(document.activeElement);
    if (e.key === "Escape" || e.key === "Tab") {
      close();
      if (e.key === "Escape") button.focus();
    } else if (e.key === "ArrowDown" || e.key === "ArrowUp") {
      e.preventDefault();
      items[(i + (e.key === "ArrowDown" ? 1 : items.length - 1)) % items.length].focus();
    }
  });
  const outside = (e) => {
    if (!el.contains(e.target)) close();
  };
  document.addEventListener("click", outside);
  signal.addEventListener("abort", () => document.removeEventListener("click", outside));
  return el;
}
