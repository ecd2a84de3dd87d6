/**
 * The Datasets view's upload card: a log dropped or browsed, units per CSV column, the
 * channels to keep and the raster to put them on (docs/data-formats.md#multi-rate), with
 * progress; and what ingest said about an upload (its notes and the masked samples per
 * channel), shown with the dataset.
 */
import { api, clearErrors, showError } from "../api.js";
import { SELECT } from "../constants.js";
import { needs, SCOPE } from "../scopes.js";
import { card, fmtBytes, fmtInt, h, icon, ICONS, splitHeader, uploadProgress } from "../dom.js";

/** The masked samples of a dataset, all channels together (0 when none were masked). */
export function maskedTotal(dataset) {
  return Object.values(dataset?.masked ?? {}).reduce((sum, n) => sum + n, 0);
}

/** A tag for a dataset row: how many samples ingest masked, per channel in its title. */
export function maskedTag(dataset) {
  const total = maskedTotal(dataset);
  if (!total) return null;
  const per = Object.entries(dataset.masked).map(([name, n]) => `${name}: ${fmtInt(n)}`);
  return h(
    "span",
    { class: "tag warn", "data-masked-total": total, title: per.join("\n") },
    `${fmtInt(total)} masked`,
  );
}

/** What ingest said about the dataset (resampling, dropped channels, masked samples), or null. */
export function ingestReport(dataset) {
  const notes = dataset?.notes ?? [];
  if (!notes.length && !maskedTotal(dataset)) return null;
  return h(
    "div",
    { class: "banner info ingest-report", role: "note", "data-ingest-report": "" },
    h("strong", {}, "On upload"),
    notes.length
      ? h(
          "ul",
          { class: "ingest-notes" },
          notes.map((n) => h("li", { "data-ingest-note": "" }, n)),
        )
      : null,
  );
}

export function uploadCard(ctx, onCreated) {
  const fileInput = h("input", {
    type: "file",
    id: "upload-file",
    name: "file",
    class: "visually-hidden",
    accept: ".csv,.txt,.mcap,.mf4,.mdf,.dat",
  });
  const nameInput = h("input", {
    type: "text",
    id: "upload-name",
    name: "name",
    placeholder: "defaults to the file name",
  });
  const rasterInput = h("input", {
    type: "text",
    id: "upload-raster",
    name: "raster",
    placeholder: "slowest kept channel",
    autocomplete: "off",
    spellcheck: "false",
    "aria-describedby": "upload-raster-help",
  });
  const channelsInput = h("input", {
    type: "text",
    id: "upload-channels",
    name: "channels",
    placeholder: "all",
    autocomplete: "off",
    spellcheck: "false",
    "aria-describedby": "upload-channels-help",
  });
  // A CSV without a time column has no time base: the rows' rate must be given (the server
  // refuses the file otherwise, naming `time`).
  const rateInput = h("input", {
    type: "number",
    id: "upload-rate",
    name: "rate_hz",
    min: "0",
    step: "any",
    placeholder: "e.g. 100",
    "data-field": "time",
    "aria-describedby": "upload-rate-help",
  });
  const rateField = h(
    "div",
    { class: "field", hidden: true, "data-upload-rate": "" },
    h("label", { for: "upload-rate" }, "Sample rate of the rows [Hz]"),
    rateInput,
    h(
      "div",
      { class: "banner warn", id: "upload-rate-help", role: "note" },
      `No time column (${TIME_COLUMNS.join(", ")}): give the rate the rows were logged at, ` +
        "or add a time column in seconds.",
    ),
  );
  const fileInfo = h("div", { class: "upload-file", hidden: true });
  const columns = h("div", { "data-upload-columns": "" });
  const progress = uploadProgress();
  const submit = h(
    "button",
    { type: "submit", class: "primary", disabled: true },
    icon(ICONS.upload),
    "Upload",
  );
  const drop = h(
    "label",
    { class: "dropzone", for: "upload-file" },
    icon(ICONS.upload),
    h("strong", {}, "Drop a log here or browse"),
    h("span", { class: "help" }, "CSV with a header row (“name [unit]”), MCAP, MDF4 or MDF3"),
    fileInput,
  );
  let file = null;
  let units = {};

  const form = h(
    "form",
    { novalidate: true, "aria-label": "Upload a log" },
    h("div", { class: "field" }, drop, fileInfo),
    columns,
    rateField,
    h("div", { class: "field" }, h("label", { for: "upload-name" }, "Dataset name"), nameInput),
    h(
      "div",
      { class: "fields two" },
      h(
        "div",
        { class: "field" },
        h("label", { for: "upload-raster" }, "Raster"),
        rasterInput,
        h(
          "div",
          { class: "help", id: "upload-raster-help" },
          "100Hz, 10ms or channel:NAME; empty: the slowest raster among the kept channels.",
        ),
      ),
      h(
        "div",
        { class: "field" },
        h("label", { for: "upload-channels" }, "Channels to keep"),
        channelsInput,
        h(
          "div",
          { class: "help", id: "upload-channels-help" },
          "Comma-separated names as recorded; empty: all.",
        ),
      ),
    ),
    h("div", { class: "banner error", "data-form-error": "", hidden: true }),
    progress.el,
    h("div", { class: "row end", style: { marginTop: "12px" } }, submit),
  );

  const choose = async (f) => {
    file = f;
    units = {};
    clearErrors(form);
    fileInfo.hidden = !f;
    submit.disabled = !f;
    columns.replaceChildren();
    if (!f) return;
    fileInfo.replaceChildren(
      h("span", { class: "name" }, f.name),
      h("span", { class: "ch-unit" }, fmtBytes(f.size)),
    );
    if (!nameInput.value) nameInput.placeholder = f.name.replace(/\.[^.]+$/, "");
    rateInput.value = "";
    rateField.hidden = true;
    if (/\.(csv|txt)$/i.test(f.name)) {
      columns.append(await columnEditor(f, units));
      rateField.hidden = await hasTimeColumn(f);
    }
  };

  fileInput.addEventListener("change", () => choose(fileInput.files[0] ?? null));
  for (const type of ["dragenter", "dragover"]) {
    drop.addEventListener(type, (e) => {
      e.preventDefault();
      drop.classList.add("over");
    });
  }
  for (const type of ["dragleave", "drop"])
    drop.addEventListener(type, () => drop.classList.remove("over"));
  drop.addEventListener("drop", (e) => {
    e.preventDefault();
    const f = e.dataTransfer?.files?.[0];
    if (f) choose(f);
  });

  form.addEventListener("submit", async (e) => {
    e.preventDefault();
    if (!file) return;
    clearErrors(form);
    const body = new FormData();
    body.append("file", file, file.name);
    body.append("name", nameInput.value.trim() || file.name.replace(/\.[^.]+$/, ""));
    const given = Object.fromEntries(Object.entries(units).filter(([, u]) => u !== null));
    if (Object.keys(given).length) body.append("units", JSON.stringify(given));
    // Blank means the server's default (the slowest raster; every channel).
    if (rasterInput.value.trim()) body.append("raster", rasterInput.value.trim());
    if (channelsInput.value.trim()) body.append("channels", channelsInput.value.trim());
    if (rateInput.value.trim()) body.append("rate_hz", rateInput.value.trim());
    submit.disabled = true;
    progress.start();
    try {
      const dataset = await api.upload("/api/datasets", body, {
        onProgress: progress.set,
        signal: ctx.signal,
      });
      progress.finish(true);
      file = null;
      fileInput.value = "";
      nameInput.value = "";
      fileInfo.hidden = true;
      columns.replaceChildren();
      rateInput.value = "";
      rateField.hidden = true;
      await onCreated(dataset);
    } catch (err) {
      progress.finish(false);
      if (err?.field === "time" || err?.field === "rate_hz") rateField.hidden = false;
      showUploadError(form, err);
    } finally {
      submit.disabled = !file;
    }
  });

  return needs(SCOPE.run, card({ title: "Upload a log", body: form }));
}

/** A problem with one CSV column is shown on that column's row; others next to the file or form. */
function showUploadError(form, err) {
  const row = err?.field ? form.querySelector(SELECT.dataColumn(err.field)) : null;
  if (row)
    return showError(form, {
      ...err,
      message: err.message,
      name: err.name,
      field: `column:${err.field}`,
    });
  return showError(form, err);
}

/** The column names the server takes as time (app/io/csv_files.py TIME_COLUMNS). */
const TIME_COLUMNS = ["time", "time_s", "t", "timestamp", "timestamps"];

/** Whether a CSV's header names a time column (or cannot be read: the server judges). */
async function hasTimeColumn(file) {
  const head = await file.slice(0, 64 * 1024).text();
  const line = head
    .replace(/^\uFEFF/, "")
    .split(/\r?\n/)
    .find((l) => l.trim() && !l.trimStart().startsWith("#"));
  if (!line) return true;
  const sep = [",", ";", "\t"]
    .map((s) => [s, line.split(s).length])
    .sort((a, b) => b[1] - a[1])[0][0];
  const names = line.split(sep).map((c) => splitHeader(c.replace(/^"|"$/g, "")).name);
  if (names.length < 2) return true;
  return names.some((n) => TIME_COLUMNS.includes(n));
}

/** Columns of a CSV header with their units; units can be filled in before upload. */
async function columnEditor(file, units) {
  const head = await file.slice(0, 64 * 1024).text();
  const firstLine = head.split(/\r?\n/, 1)[0] ?? "";
  const sep = [",", ";", "\t"]
    .map((s) => [s, firstLine.split(s).length])
    .sort((a, b) => b[1] - a[1])[0][0];
  const cols = firstLine.split(sep).map((c) => splitHeader(c.replace(/^"|"$/g, "")));
  if (cols.length < 2)
    return h(
      "div",
      { class: "banner warn" },
      "Could not read a header row; the server will check the file.",
    );
  const rows = cols.map((c, k) => {
    const id = `unit-${k}`;
    const input = h("input", {
      type: "text",
      id,
      value: c.unit,
      placeholder: "unit",
      "aria-label": `Unit of ${c.name}`,
      name: `units.${c.name}`,
      "data-column": c.name,
      "data-field": `column:${c.name}`,
      oninput: (e) => {
        units[c.name] = e.target.value.trim() === c.unit ? null : e.target.value.trim();
      },
    });
    return h("tr", {}, h("td", { class: "mono" }, c.name), h("td", {}, input));
  });
  return h(
    "div",
    { class: "field" },
    h("div", { class: "label" }, `Columns (${cols.length}) and units`),
    h(
      "div",
      { class: "values-grid columns-table", style: { maxHeight: "220px" } },
      h(
        "table",
        { class: "data" },
        h(
          "thead",
          {},
          h("tr", {}, h("th", { scope: "col" }, "Column"), h("th", { scope: "col" }, "Unit")),
        ),
        h("tbody", {}, rows),
      ),
    ),
    h(
      "div",
      { class: "help" },
      "Units come from “name [unit]” headers; fill in any that are missing.",
    ),
  );
}
