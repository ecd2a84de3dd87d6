/** The table of ECUs (GET /api/ecus): name, values format, number of characteristics, delete. */
import { api, showError } from "../../api.js";
import { confirmDialog, fmtDate, fmtInt, h, icon, ICONS, toast } from "../../dom.js";
import { SCOPE } from "../../scopes.js";

/** "hex" → "HEX"; no values file → "A2L only". */
export function valuesLabel(format) {
  return format ? format.toUpperCase() : "A2L only";
}

/**
 * @param {HTMLElement} host  where the table goes
 * @param {{signal: AbortSignal, onChange?: () => void}} opts
 * @returns {{refresh: () => Promise<void>}}
 */
export function ecuList(host, { signal, onChange = () => {} }) {
  let ecus = [];

  async function refresh() {
    try {
      ecus = await api.all("/api/ecus", { signal });
    } catch (err) {
      if (err.name === "AbortError") return;
      host.replaceChildren(h("div", { class: "banner error", role: "alert" }, err.message));
      return;
    }
    render();
  }

  function render() {
    if (!ecus.length) {
      host.replaceChildren(
        h("div", { class: "empty" }, "No ECUs yet — add an A2L, with its HEX, S19, DCM or CDFX."),
      );
      return;
    }
    host.replaceChildren(
      h(
        "div",
        { class: "table-wrap" },
        h(
          "table",
          { class: "data", "data-ecu-list": "" },
          h(
            "thead",
            {},
            h(
              "tr",
              {},
              h("th", { scope: "col" }, "Name"),
              h("th", { scope: "col" }, "Values"),
              h("th", { scope: "col", class: "num" }, "Characteristics"),
              h("th", { scope: "col" }, "A2L"),
              h("th", { scope: "col" }, "Added"),
              h(
                "th",
                { scope: "col", class: "num" },
                h("span", { class: "visually-hidden" }, "Actions"),
              ),
            ),
          ),
          h("tbody", {}, ecus.map(row)),
        ),
      ),
    );
  }

  function row(ecu) {
    return h(
      "tr",
      { dataset: { ecuId: ecu.id } },
      h(
        "td",
        { class: "wrap" },
        h("a", { href: `/ecus/${ecu.id}`, "data-open-ecu": ecu.id }, ecu.name),
      ),
      h("td", {}, h("span", { class: "tag" }, valuesLabel(ecu.values_format))),
      h("td", { class: "num" }, fmtInt(ecu.characteristics)),
      h("td", {}, h("code", { title: ecu.a2l_sha256 }, (ecu.a2l_sha256 ?? "").slice(0, 10))),
      h("td", {}, fmtDate(ecu.created_at)),
      h(
        "td",
        { class: "num" },
        h(
          "button",
          {
            class: "small danger icon",
            type: "button",
            "aria-label": `Delete ECU ${ecu.name}`,
            title: "Delete",
            "data-needs": SCOPE.admin,
            onclick: () => remove(ecu),
          },
          icon(ICONS.trash),
        ),
      ),
    );
  }

  async function remove(ecu) {
    const ok = await confirmDialog(`Delete ECU “${ecu.name}” and its values?`, {
      title: "Delete ECU",
      confirmLabel: "Delete",
      danger: true,
    });
    if (!ok) return;
    try {
      await api.del(`/api/ecus/${ecu.id}`);
      toast(`Deleted ECU ${ecu.name}.`);
      await refresh();
      onChange();
    } catch (err) {
      showError(host, err);
    }
  }

  return { refresh };
}
