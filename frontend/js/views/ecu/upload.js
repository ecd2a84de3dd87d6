/**
 * The "Add an ECU" card: an A2L (required) and, optionally, the ECU's current values as a
 * memory image (Intel HEX, Motorola S-record) or a calibration data file (DCM, CDFX), sent as
 * one multipart POST /api/ecus (docs/calibration.md#dashboard). The API names the field a
 * problem belongs to ("a2l" or "values"); the message is shown next to that file input.
 */
import { api, clearErrors, showError } from "../../api.js";
import { card, fmtBytes, h, icon, ICONS, toast, uploadProgress } from "../../dom.js";
import { needs, SCOPE } from "../../scopes.js";

/** What the values input accepts (the API detects the format from the content). */
export const VALUES_ACCEPT = ".hex,.ihex,.s19,.s28,.s37,.srec,.mot,.dcm,.cdfx,.xml";

/** @param {{signal: AbortSignal, onCreated: (ecu: object) => void}} opts */
export function uploadCard({ signal, onCreated }) {
  const a2lInput = h("input", { type: "file", id: "ecu-a2l", name: "a2l", accept: ".a2l" });
  const valuesInput = h("input", {
    type: "file",
    id: "ecu-values",
    name: "values",
    accept: VALUES_ACCEPT,
  });
  const nameInput = h("input", {
    type: "text",
    id: "ecu-name",
    name: "name",
    placeholder: "defaults to the A2L file name",
  });
  const progress = uploadProgress();
  const submit = h(
    "button",
    { type: "submit", class: "primary", disabled: true, "data-ecu-upload": "" },
    icon(ICONS.upload),
    "Add ECU",
  );
  const sizeOf = (input) => (input.files[0] ? fmtBytes(input.files[0].size) : "");
  const a2lInfo = h("div", { class: "help" });
  const valuesInfo = h("div", { class: "help" });

  const form = h(
    "form",
    { novalidate: true, "aria-label": "Add an ECU", "data-ecu-form": "" },
    h(
      "div",
      { class: "field" },
      h("label", { for: "ecu-a2l" }, "A2L description (ASAM MCD-2 MC)"),
      a2lInput,
      a2lInfo,
    ),
    h(
      "div",
      { class: "field" },
      h("label", { for: "ecu-values" }, "Current values (optional)"),
      valuesInput,
      h("div", { class: "help" }, "Intel HEX or S-record image, DCM or CDFX."),
      valuesInfo,
    ),
    h("div", { class: "field" }, h("label", { for: "ecu-name" }, "Name"), nameInput),
    h("div", { class: "banner error", "data-form-error": "", hidden: true }),
    progress.el,
    h("div", { class: "row end", style: { marginTop: "12px" } }, submit),
  );

  a2lInput.addEventListener("change", () => {
    clearErrors(form);
    const f = a2lInput.files[0];
    submit.disabled = !f;
    a2lInfo.textContent = sizeOf(a2lInput);
    if (f && !nameInput.value) nameInput.placeholder = f.name.replace(/\.[^.]+$/, "");
  });
  valuesInput.addEventListener("change", () => {
    clearErrors(form);
    valuesInfo.textContent = sizeOf(valuesInput);
  });

  form.addEventListener("submit", async (e) => {
    e.preventDefault();
    const a2l = a2lInput.files[0];
    if (!a2l) return;
    clearErrors(form);
    const body = new FormData();
    body.append("a2l", a2l, a2l.name);
    const values = valuesInput.files[0];
    if (values) body.append("values", values, values.name);
    body.append("name", nameInput.value.trim() || a2l.name.replace(/\.[^.]+$/, ""));
    submit.disabled = true;
    progress.start();
    try {
      const ecu = await api.upload("/api/ecus", body, { onProgress: progress.set, signal });
      progress.finish(true);
      form.reset();
      a2lInfo.textContent = "";
      valuesInfo.textContent = "";
      showNotes(ecu);
      onCreated(ecu);
    } catch (err) {
      progress.finish(false);
      showError(form, err);
    } finally {
      submit.disabled = !a2lInput.files[0];
    }
  });

  return needs(SCOPE.run, card({ title: "Add an ECU", body: form }));
}

/** What the upload check noticed without refusing the files (names the A2L lacks). */
export function showNotes(ecu) {
  if (ecu.notes?.length) toast(ecu.notes.join(" "), { ms: 12000 });
}
