/**
 * ECU view. /ecus: add an ECU (its A2L plus, optionally, a HEX, S19, DCM or CDFX with the
 * current values) and list the ECUs. /ecus/{id}?q=&type=&map=: browse and search the ECU's
 * characteristics, replace its values file, and open one characteristic: its A2L facts and
 * its current values as a heatmap with units, with "Adapt this map" (New run prefilled, see
 * views/new-run/ecu-prefill.js). The parts: upload.js, list.js, browser.js, detail.js.
 * See docs/calibration.md#dashboard.
 */
import { api, clearErrors, request, showError } from "../../api.js";
import { card, fmtInt, h, icon, ICONS, pageHead, toast } from "../../dom.js";
import { needs, SCOPE } from "../../scopes.js";
import { DEFAULT_TYPES, mapBrowser, TYPES } from "./browser.js";
import { renderDetail } from "./detail.js";
import { ecuList, valuesLabel } from "./list.js";
import { showNotes, uploadCard, VALUES_ACCEPT } from "./upload.js";

export const title = "ECUs";

export async function mount(root, ctx) {
  if (ctx.params.id) return mountEcu(root, ctx, Number(ctx.params.id));
  return mountList(root, ctx);
}

/** /ecus: the upload card beside the list; a new ECU opens at once. */
function mountList(root, ctx) {
  const listHost = h("div", { "data-ecus": "" }, h("div", { class: "loading" }, "Loading ECUs…"));
  const list = ecuList(listHost, { signal: ctx.signal });
  root.append(
    pageHead({
      title: "ECUs",
      sub: "Bring an ECU's A2L and its current values, browse its maps, and adapt one from a log.",
    }),
    h(
      "div",
      { class: "grid side-l" },
      uploadCard({ signal: ctx.signal, onCreated: (ecu) => ctx.navigate(`/ecus/${ecu.id}`) }),
      card({ title: "Your ECUs", bodyCls: "flush", body: listHost }),
    ),
  );
  return list.refresh();
}

/** /ecus/{id}: the map browser beside the chosen characteristic. */
async function mountEcu(root, ctx, id) {
  let ecu = await api.get(`/api/ecus/${id}`, { signal: ctx.signal });
  const q = ctx.query.get("q") ?? "";
  const typeParam = ctx.query.get("type");
  const types =
    typeParam === null ? [...DEFAULT_TYPES] : typeParam.split(",").filter((t) => TYPES.includes(t));
  let selected = ctx.query.get("map") || null;
  let cleanupDetail = () => {};
  let shown = 0;

  const sub = h("div", { class: "run-head-meta", "data-ecu-meta": "" });
  const describe = () =>
    sub.replaceChildren(
      h("span", { class: "tag", "data-values-format": "" }, valuesLabel(ecu.values_format)),
      h("span", {}, `${fmtInt(ecu.characteristics)} characteristics`),
      h("code", { title: ecu.a2l_sha256 }, `A2L ${(ecu.a2l_sha256 ?? "").slice(0, 10)}`),
    );
  describe();
  const detailHost = h("div", { "data-ecu-detail": "" });
  const syncUrl = (query) => ctx.setQuery({ q: query.q, type: query.type, map: selected });
  let query = { q, type: typeParam === null ? undefined : types.join(",") };

  const browser = mapBrowser({
    ecuId: id,
    q,
    types,
    selected,
    signal: ctx.signal,
    onSelect: (name) => {
      selected = name;
      syncUrl(query);
      showDetail();
    },
    onQuery: (text, picked) => {
      query = { q: text, type: picked.join(",") };
      syncUrl(query);
    },
  });

  root.append(
    pageHead({
      crumbs: [h("a", { href: "/ecus" }, "ECUs"), ` / #${ecu.id}`],
      title: ecu.name,
      sub,
      actions: [valuesButton()],
    }),
    h(
      "div",
      { class: "grid side-l" },
      card({ title: "Characteristics", body: browser.el }),
      detailHost,
    ),
  );

  async function showDetail() {
    cleanupDetail();
    cleanupDetail = () => {};
    if (!selected) {
      detailHost.replaceChildren(
        card({
          title: "Pick a characteristic",
          body: h(
            "p",
            { class: "help" },
            "Search by name or description on the left; a MAP or CURVE can be adapted from a log.",
          ),
        }),
      );
      return;
    }
    const seq = ++shown;
    const cleanup = await renderDetail(detailHost, {
      ecu,
      name: selected,
      signal: ctx.signal,
      current: () => seq === shown && !ctx.signal.aborted,
    });
    // An older answer (another map was picked meanwhile) drew nothing and keeps no cleanup.
    if (seq === shown) cleanupDetail = cleanup;
  }

  /** "Replace values": PUT /api/ecus/{id}/values with a new HEX, S19, DCM or CDFX. */
  function valuesButton() {
    const input = h("input", {
      type: "file",
      id: "ecu-replace-values",
      name: "values",
      class: "visually-hidden",
      accept: VALUES_ACCEPT,
    });
    const el = needs(
      SCOPE.run,
      h(
        "div",
        { class: "ecu-values-action" },
        h(
          "label",
          { class: "button", for: "ecu-replace-values" },
          icon(ICONS.upload),
          "Replace values",
        ),
        input,
      ),
    );
    input.addEventListener("change", async () => {
      const f = input.files[0];
      if (!f) return;
      clearErrors(el);
      const body = new FormData();
      body.append("values", f, f.name);
      try {
        ecu = await request("PUT", `/api/ecus/${id}/values`, { body, signal: ctx.signal });
        describe();
        toast(`Values of ${ecu.name} replaced from ${f.name}.`);
        showNotes(ecu);
        await showDetail();
      } catch (err) {
        showError(el, err);
      } finally {
        input.value = "";
      }
    });
    return el;
  }

  await showDetail();
  return () => cleanupDetail();
}
