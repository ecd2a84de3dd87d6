/**
 * The one polling loop of the dashboard: views refresh what the live stream does not carry
 * (a group's runs, a comparison, a run's versions, the server's health) by calling a load
 * function again and again, never overlapping, until it says stop or the view is left.
 */

/**
 * Call `load()` now (or first after `every` ms with `{ now: false }`) and again `every` ms
 * after each call has settled, for as long as it resolves truthy; stops when `signal` aborts
 * (no signal: for the life of the page). An AbortError ends the loop quietly; another error
 * of the first call rejects the returned promise (the view's first render failed), of a later
 * call is logged and ends the loop. Resolves when the first call is done.
 *
 * @param {AbortSignal | null} signal
 * @param {() => unknown} load  returns (or resolves to) whether to call again
 * @param {number} every  ms between the end of one call and the start of the next
 */
export function poll(signal, load, every, { now = true } = {}) {
  let timer = 0;
  signal?.addEventListener("abort", () => clearTimeout(timer));
  const again = () => {
    if (!signal?.aborted) timer = setTimeout(() => tick().catch((err) => console.warn(err)), every);
  };
  const tick = async () => {
    let more;
    try {
      more = await load();
    } catch (err) {
      if (err?.name === "AbortError") return;
      throw err;
    }
    if (more) again();
  };
  if (now) return tick();
  again();
  return Promise.resolve();
}
