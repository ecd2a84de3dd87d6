/** DOMContentLoaded, first content and plot (ms since navigation start), bytes fetched. */
() => {
  const nav = performance.getEntriesByType("navigation")[0];
  const bytes = performance
    .getEntriesByType("resource")
    .reduce((n, r) => n + r.transferSize, nav.transferSize);
  return {
    dcl: nav.domContentLoadedEventEnd,
    content: window.__seen.content,
    plot: window.__seen.plot,
    bytes,
  };
};
