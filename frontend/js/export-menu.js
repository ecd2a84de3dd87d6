/** The "Export" menu button of a run: one item per format, keyboard operable (menu pattern). */
import { api, showError } from "./api.js";
import { EXPORT_FORMATS, SEL } from "./constants.js";
import { h, icon, ICONS } from "./dom.js";

/**
 * @param {number} runId
 * @param {{versionId: () => number|null, errorHost: HTMLElement, signal: AbortSignal}} opts
 *   versionId: the version to export (null: the run's final map)
 */
export function exportMenu(runId, { versionId, errorHost, signal }) {
  const list = h(
    "div",
    { class: "menu-list", role: "menu", hidden: true },
    EXPORT_FORMATS.map((f) =>
      h(
        "button",
        {
          type: "button",
          role: "menuitem",
          tabindex: "-1",
          "data-export": f.value,
          onclick: async () => {
            close();
            const vid = versionId();
            try {
              await api.download(
                `/api/runs/${runId}/export`,
                { format: f.value, version: vid ?? undefined },
                `run-${runId}.${f.value}`,
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
