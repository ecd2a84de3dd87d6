/**
 * Records when the view's content and its first plot first appear (performance.now(): ms
 * since the navigation started), watched from the moment the document exists. Called with
 * [contentSelector, plotSelector] from an init script (see test_views.py).
 */
([content, plot]) => {
  window.__seen = { content: null, plot: null };
  const look = () => {
    if (window.__seen.content === null && document.querySelector(content))
      window.__seen.content = performance.now();
    if (window.__seen.plot === null && document.querySelector(plot))
      window.__seen.plot = performance.now();
    return window.__seen.content !== null && window.__seen.plot !== null;
  };
  const watch = new MutationObserver(() => look() && watch.disconnect());
  watch.observe(document, { childList: true, subtree: true });
};
