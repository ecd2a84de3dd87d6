/** Names shared across modules: selectors of the shell, event names, storage keys, limits. */

export const SEL = Object.freeze({
  main: "#main",
  navLink: "a[data-nav]",
  link: "a[href]",
  currentRun: "[data-current-run]",
  toasts: "[data-toasts]",
  themeToggle: "[data-theme-toggle]",
  themeLabel: "[data-theme-label]",
  health: "[data-health]",
  pageTitle: "[data-page-title]",
  tokenDialog: "dialog[data-token]",
  fieldError: ".field-error",
  formError: "[data-form-error]",
  invalid: "[aria-invalid]",
  field: ".field",
  cardTitle: ".card-head h2",
  tab: "[role=tab]",
  tabPanel: "[role=tabpanel]",
  menuItem: "[role=menuitem]",
  legend: "legend",
  plotlyPreload: "link[data-plotly]",
});

/** Selectors built from a value (CSS-escaped). */
export const SELECT = Object.freeze({
  dataField: (key) => `[data-field="${CSS.escape(key)}"]`,
  name: (key) => `[name="${CSS.escape(key)}"]`,
  dataColumn: (key) => `[data-column="${CSS.escape(key)}"]`,
  sortButton: (key) => `[data-sort="${CSS.escape(key)}"]`,
  id: (id) => `#${CSS.escape(id)}`,
});

export const EVT = Object.freeze({
  /** dispatched on window after the theme changes; plots re-colour themselves */
  themeChange: "mapwise:theme",
  /** dispatched on window when a view wants the nav to show the run it displays */
  currentRun: "mapwise:current-run",
});

export const STORAGE = Object.freeze({
  theme: "mapwise.theme",
  token: "mapwise.token",
  mapMode: "mapwise.map-mode",
  /** sessionStorage: the New-run form being filled in (restored on reload) */
  newRunDraft: "mapwise.new-run-draft",
});

/** Performance marks (performance.mark) the router sets; tests and profiling read them. */
export const MARK = Object.freeze({
  viewMounted: "mapwise:view-mounted",
});

/** Live rendering: at most 20 frames per second (issue 7). */
export const FRAME_INTERVAL_MS = 50;
/** Points kept per live time series before the oldest half is decimated 2:1. */
export const SERIES_CAP = 12000;
/** Points of the operating-point trail drawn over the map. */
export const TRAIL_POINTS = 400;
/** Reconnect backoff of the live stream. */
export const BACKOFF = Object.freeze({ initialMs: 500, maxMs: 10000, factor: 2 });

export const RUN_DONE = new Set(["succeeded", "failed", "cancelled", "interrupted"]);
/** Sweeps and batches are polled this often while any of their runs is queued or running. */
export const GROUP_POLL_MS = 1000;
/** A sweep's runs are drawn on a log axis when the parameter's values span more than this ratio. */
export const LOG_AXIS_RATIO = 10;
/** Standardised deviations |z| beyond this mark a vehicle's cell as deviating (the API's count). */
export const DEVIATION_Z = 3;
/** The fixed colour range of the deviation maps. */
export const DEVIATION_RANGE = Object.freeze([-5, 5]);
export const RUN_ACTIVE = new Set(["queued", "running"]);

export const PACES = Object.freeze([
  { value: "max", label: "As fast as possible" },
  { value: "1", label: "1× real time" },
  { value: "2", label: "2×" },
  { value: "5", label: "5×" },
  { value: "10", label: "10×" },
  { value: "20", label: "20×" },
  { value: "50", label: "50×" },
  { value: "100", label: "100×" },
  { value: "custom", label: "Custom…" },
]);

export const EXPORT_FORMATS = Object.freeze([
  { value: "json", label: "JSON map document" },
  { value: "csv", label: "CSV" },
  { value: "dcm", label: "DCM (calibration tools)" },
  { value: "mcap", label: "MCAP (Foxglove)" },
]);
