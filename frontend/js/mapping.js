/**
 * Which dataset column feeds which estimator signal. The catalog lists each estimator's
 * roles ({role, description, unit}); table filters also take one column per table axis.
 */

export function needsTable(est) {
  return Boolean(est?.needs_table ?? est?.kind === "table-filter");
}

export function rolesOf(est) {
  return (est?.signals ?? []).filter((s) => s && s.role);
}

const normal = (s) =>
  String(s ?? "")
    .toLowerCase()
    .replace(/[^a-z0-9]+/g, "");

/** The most plausible column for a role: same name, name containing the role, then unit. */
export function guessColumn(role, channels, taken = new Set()) {
  const free = channels.filter((c) => !taken.has(c.name));
  const r = normal(role.role);
  const base = r.replace(/channel$/, "");
  const unit = normal(role.unit);
  return (
    (
      free.find((c) => role.default && c.name === role.default) ||
      free.find((c) => normal(c.name) === r) ||
      free.find((c) => base && normal(c.name).startsWith(base)) ||
      free.find((c) => base && normal(c.name).includes(base)) ||
      free.find((c) => unit && normal(c.unit) === unit) ||
      null
    )?.name ?? null
  );
}

/** Output and axes for a table filter: the last channel is usually the measured output. */
export function guessTable(channels) {
  const usable = channels.filter((c) => !/^time|^t$/i.test(c.name));
  if (!usable.length) return { y: null, axes: [] };
  const y =
    usable.find((c) => /^y$|nox|output|lambda|maf|measured/i.test(c.name))?.name ??
    usable.at(-1).name;
  const axes = usable
    .filter((c) => c.name !== y)
    .slice(0, 2)
    .map((c) => c.name);
  return { y, axes };
}

/** "y:nox_ppm,speed:speed_rpm" ⇄ {y: "nox_ppm", speed: "speed_rpm"} (for URLs). */
export function encodeSignals(signals) {
  return Object.entries(signals)
    .filter(([, v]) => v)
    .map(([k, v]) => `${k}:${v}`)
    .join(",");
}

export function decodeSignals(text) {
  const out = {};
  for (const part of String(text ?? "").split(",")) {
    const i = part.indexOf(":");
    if (i > 0) out[part.slice(0, i)] = part.slice(i + 1);
  }
  return out;
}

export const KIND_TITLES = {
  "table-filter": "Map filters",
  "maf-observer": "MAF observers",
  torque: "Torque estimators",
};
