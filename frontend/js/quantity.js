/**
 * What a run's map holds, by name and unit: its output column (table filters, with the
 * column's unit from its dataset), else the map observers' quantity. The server's one source
 * is app/services/truth_map.py (map_quantity, MAP_QUANTITY), which names the exports; these
 * are its names and units, read by the run view, Compare, Versions and Sweeps.
 */

/** The map observers' quantities: LPV's additive MAF error ΔW_c, the EKF's relative error q. */
const MAP_QUANTITY = {
  lpv: { name: "MAF error ΔW_c", unit: "kg/s" },
  "ekf-map": { name: "relative MAF error q", unit: "-" },
};

/** {name, unit} of a run's map values when it has no output column, else null. */
export function mapQuantity(run) {
  return MAP_QUANTITY[run?.estimator] ?? null;
}

/**
 * {label, unit} of a run's map values: the output column and its unit (from `datasets`, a
 * list of dataset documents, else the run's config), else the map quantity, else "value".
 */
export function runQuantity(run, datasets = []) {
  const output = run?.signals?.y ?? run?.config?.output;
  if (output) {
    const ds = datasets.find((d) => d.id === run.dataset_id);
    const unit = ds?.channels?.find((c) => c.name === output)?.unit ?? run.config?.output_unit;
    return { label: output, unit: unit ?? "" };
  }
  const q = mapQuantity(run);
  return q ? { label: q.name, unit: q.unit } : { label: "value", unit: "" };
}
