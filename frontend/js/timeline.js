/**
 * The versions timeline of a run: a slider over the stored map versions (plus "live" while
 * the run goes on), a play button that steps through them, the label of the version shown
 * and "save as base map". It fetches versions itself and hands each one to onShow; the version
 * a person picks is reported to onScrub (the view keeps it in its URL, so a reload shows it again).
 * Versions are named by their number in the run, v1…vN (`number` of the API's documents); the
 * database `id` only addresses them in API calls.
 */
import { api, showError } from "./api.js";
import { fmt, fmtInt, h, icon, ICONS, toast } from "./dom.js";
import { SCOPE } from "./scopes.js";

const PLAY_STEP_MS = 650;
const PLAY_TOTAL_MS = 8000;

export class VersionTimeline {
  /**
   * @param {object} opts
   * @param {number} opts.runId
   * @param {() => boolean} opts.isLive     whether the run is still going
   * @param {(doc: object, version: object, how: {quiet: boolean}) => void} opts.onShow
   * @param {() => void} opts.onLive        back to the live frames
   * @param {(versions: object[]) => void} [opts.onList]
   * @param {() => string} opts.baseMapName name for "save as base map"
   * @param {string|number|null} [opts.initialVersion] version number (1…n) to show first, from
   *   the URL's ?version=N; an old link's database id is taken when no version has that number
   * @param {string|number|null} [opts.initialVersionId] database id to show first (?version_id=)
   * @param {(version: object|null) => void} [opts.onScrub] a version was picked (null: back to live/final)
   */
  constructor({
    runId,
    isLive,
    onShow,
    onLive,
    onList,
    baseMapName,
    initialVersion = null,
    initialVersionId = null,
    onScrub = null,
  }) {
    Object.assign(this, {
      runId,
      isLive,
      onShow,
      onLive,
      onList,
      baseMapName,
      initialVersion: parseWanted(initialVersion),
      initialVersionId: parseWanted(initialVersionId),
      onScrub,
    });
    this.versions = [];
    this.docs = new Map();
    this.viewing = null;
    this.showingInitial = false;
    this.playing = 0;

    this.slider = h("input", {
      type: "range",
      id: "version-slider",
      min: "0",
      max: "0",
      value: "0",
      step: "1",
      "aria-label": "Map version",
      "data-version-slider": "",
    });
    this.playButton = h(
      "button",
      {
        type: "button",
        class: "icon",
        "aria-label": "Play the map's evolution",
        "data-play": "",
        onclick: () => this.togglePlay(),
      },
      icon(ICONS.play, { filled: true }),
    );
    this.where = h("div", { class: "where", "aria-live": "polite", "data-version-where": "" });
    this.ticks = h("div", { class: "timeline-ticks", "aria-hidden": "true" });
    this.liveButton = h(
      "button",
      {
        type: "button",
        class: "small",
        hidden: true,
        "data-live": "",
        onclick: () => this.backToLive(),
      },
      "Back to live",
    );
    this.note = h("span", { class: "viewing", hidden: true, "data-viewing": "" });
    // A ?version= that names no version of this run says so (never silently shows another).
    this.missing = h("div", {
      class: "banner warn",
      role: "alert",
      hidden: true,
      "data-version-missing": "",
    });
    this.labelInput = h("input", {
      type: "text",
      id: "version-label",
      placeholder: "e.g. release candidate",
      "data-field": "label",
    });
    this.labelForm = h(
      "form",
      {
        class: "row",
        novalidate: true,
        "aria-label": "Label this version",
        "data-needs": SCOPE.run,
      },
      h("label", { for: "version-label", style: { margin: 0 } }, "Label"),
      h("div", { class: "field", style: { margin: 0, flex: 1 } }, this.labelInput),
      h(
        "button",
        { type: "submit", class: "small", "data-save-label": "" },
        icon(ICONS.tag),
        "Save label",
      ),
      h(
        "button",
        {
          type: "button",
          class: "small",
          "data-base-map": "",
          "data-needs": SCOPE.admin,
          onclick: () => this.saveBaseMap(),
        },
        "Save as base map",
      ),
    );
    this.labelForm.addEventListener("submit", (e) => {
      e.preventDefault();
      this.saveLabel();
    });
    this.slider.addEventListener("input", () => this.scrubTo(Number(this.slider.value)));
    this.el = h(
      "div",
      {},
      this.missing,
      h(
        "div",
        { class: "timeline" },
        this.playButton,
        h("div", {}, this.slider, this.ticks),
        this.where,
      ),
      h("div", { style: { marginTop: "12px" } }, this.labelForm),
    );
  }

  /** Fetch the version list; with nothing chosen, a finished run shows its final version. */
  async refresh({ signal } = {}) {
    let body;
    try {
      body = await api.get(`/api/runs/${this.runId}/versions`, { signal });
    } catch {
      return;
    }
    this.versions = Array.isArray(body) ? body : (body.items ?? []);
    const live = this.isLive();
    const n = this.versions.length;
    this.slider.max = String(live ? n : Math.max(0, n - 1));
    this.slider.disabled = n === 0;
    this.playButton.disabled = n < 2;
    const span = Math.max(1, Number(this.slider.max));
    this.ticks.replaceChildren(
      ...this.versions.map((v, k) =>
        h("span", {
          class: v.label ? "labelled" : null,
          title: v.label ?? "",
          style: { left: `calc(${(100 * k) / span}% - 1px)` },
        }),
      ),
    );
    this.onList?.(this.versions);
    const wanted = this.viewing ? -1 : this.wantedIndex(live);
    if (wanted >= 0 && !this.viewing) {
      // A refresh that overlaps this one must not put the final version over it.
      this.initialVersion = null;
      this.initialVersionId = null;
      this.showingInitial = true;
      try {
        await this.scrubTo(wanted);
      } finally {
        this.showingInitial = false;
      }
    } else if (!this.viewing && !this.showingInitial) {
      this.slider.value = this.slider.max;
      if (!live && n) await this.scrubTo(n - 1, { quiet: true });
      else this.describe();
    }
  }

  /**
   * The index of the version the URL asked for, -1 if none was or it is not there: by number
   * (?version=N), by database id (?version_id=ID), or an old link's ?version=ID when no version
   * has that number. What is not there is said in the banner; while the run goes on, a number
   * still to come stays wanted.
   */
  wantedIndex(live) {
    const { initialVersion: n, initialVersionId: id } = this;
    if (n === null && id === null) return -1;
    const byNumber = (x) => this.versions.findIndex((v) => (v.number ?? 0) === x);
    const byId = (x) => this.versions.findIndex((v) => v.id === x);
    let k = -1;
    if (typeof n === "number") k = byNumber(n);
    if (k < 0 && typeof id === "number") k = byId(id);
    if (k < 0 && typeof n === "number" && id === null) k = byId(n);
    if (k >= 0) {
      this.missing.hidden = true;
      return k;
    }
    const count = this.versions.length;
    const has = count ? `it has v1…v${count}` : "it has no versions yet";
    let text;
    if (typeof n === "string" || typeof id === "string") {
      text = `“${n ?? id}” is not a version number; ${has}.`;
    } else if (n !== null) {
      text = `Run ${this.runId} has no version ${n}${live ? " yet" : ""} (${has}).`;
    } else {
      text = `Run ${this.runId} has no version with id ${id} (${has}).`;
    }
    this.missing.textContent = text;
    this.missing.hidden = false;
    // Only a number the live run may still reach is kept; anything else is settled.
    if (!(live && typeof n === "number" && id === null)) {
      this.initialVersion = null;
      this.initialVersionId = null;
    }
    return -1;
  }

  describe() {
    const k = Number(this.slider.value);
    const v = this.versions[k];
    if (!v) {
      this.where.textContent = this.isLive()
        ? `live · ${this.versions.length} version(s) so far`
        : "no versions";
      this.slider.setAttribute("aria-valuetext", this.where.textContent);
      return;
    }
    const name = `v${v.number ?? k + 1}`;
    this.where.replaceChildren(
      h("b", { "data-version-number": "" }, name),
      ` · version ${k + 1} of ${this.versions.length} · t = ${fmt(v.time_s, 4)} s · step ${fmtInt(v.step)}` +
        (v.final ? " · final" : "") +
        (v.label ? ` · “${v.label}”` : ""),
    );
    this.slider.setAttribute("aria-valuetext", `${name} of ${this.versions.length}`);
  }

  doc(v) {
    if (!this.docs.has(v.id)) {
      const load = api.get(`/api/runs/${this.runId}/versions/${v.id}`).catch((err) => {
        this.docs.delete(v.id);
        throw err;
      });
      this.docs.set(v.id, load);
    }
    return this.docs.get(v.id);
  }

  /** Show version k (quiet: the automatic "final version" display, no "viewing" note). */
  async scrubTo(k, { quiet = false } = {}) {
    const v = this.versions[k];
    const live = this.isLive();
    if (!v) {
      if (live) this.backToLive();
      return;
    }
    this.slider.value = String(k);
    let doc;
    try {
      doc = await this.doc(v);
    } catch (err) {
      showError(this.labelForm, err);
      return;
    }
    if (Number(this.slider.value) !== k) return; // the user moved on meanwhile
    this.viewing = { ...v, doc };
    this.labelInput.value = v.label ?? "";
    const noted = live || !v.final;
    this.note.hidden = !noted;
    this.note.textContent = noted ? `viewing v${v.number ?? k + 1}` : "";
    if (!quiet) {
      // A version picked settles what the URL asked for (a number still to come included).
      this.missing.hidden = true;
      this.initialVersion = null;
      this.initialVersionId = null;
    }
    this.liveButton.hidden = !live;
    this.describe();
    this.onShow(doc, v, { quiet });
    if (!quiet) this.onScrub?.(v);
  }

  /** Redraw what is shown (e.g. after a theme change). */
  reshow() {
    if (this.viewing) this.scrubTo(Number(this.slider.value), { quiet: true });
  }

  backToLive() {
    this.stopPlay();
    this.viewing = null;
    this.note.hidden = true;
    this.liveButton.hidden = true;
    this.slider.value = this.slider.max;
    this.describe();
    this.onScrub?.(null);
    this.onLive();
  }

  togglePlay() {
    if (this.playing) return this.stopPlay();
    const n = this.versions.length;
    if (n < 2) return undefined;
    let k = Number(this.slider.value) >= n - 1 ? 0 : Number(this.slider.value);
    this.playButton.replaceChildren(icon(ICONS.pause, { filled: true }));
    this.playButton.setAttribute("aria-label", "Pause");
    const step = async () => {
      await this.scrubTo(k);
      k += 1;
      if (k >= n) return this.stopPlay();
      this.playing = setTimeout(step, Math.max(120, Math.min(PLAY_STEP_MS, PLAY_TOTAL_MS / n)));
      return undefined;
    };
    this.playing = setTimeout(step, 0);
    return undefined;
  }

  stopPlay() {
    clearTimeout(this.playing);
    this.playing = 0;
    this.playButton.replaceChildren(icon(ICONS.play, { filled: true }));
    this.playButton.setAttribute("aria-label", "Play the map's evolution");
  }

  /** The version the label and "save as base map" act on: the one shown, else the latest. */
  current() {
    return this.viewing ?? this.versions.at(-1) ?? null;
  }

  async saveLabel() {
    const v = this.current();
    if (!v) return;
    try {
      const updated = await api.patch(`/api/runs/${this.runId}/versions/${v.id}`, {
        label: this.labelInput.value.trim() || null,
      });
      toast(updated.label ? `Version labelled “${updated.label}”.` : "Label removed.");
      if (this.viewing?.id === v.id) this.viewing = { ...this.viewing, label: updated.label };
      await this.refresh();
      this.describe();
    } catch (err) {
      showError(this.labelForm, err);
    }
  }

  async saveBaseMap() {
    const v = this.current();
    if (!v) return;
    try {
      const map = await api.post("/api/base-maps", {
        run_id: this.runId,
        version_id: v.id,
        name: `${this.baseMapName()} v${v.number}`,
      });
      toast(`Saved base map #${map.id} “${map.name}”.`);
    } catch (err) {
      showError(this.labelForm, err);
    }
  }

  destroy() {
    this.stopPlay();
  }
}

/** A version asked for in the URL: a positive integer, else the text as given (null: none). */
function parseWanted(value) {
  if (value === null || value === undefined || value === "") return null;
  const text = String(value).trim();
  return /^[1-9]\d{0,9}$/.test(text) ? Number(text) : text;
}
