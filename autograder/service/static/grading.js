// Keyboard shortcuts of the manual grading page (listed on the page). Nothing remote.
"use strict";
(function () {
  document.addEventListener("keydown", (e) => {
    const target = e.target;
    if (e.ctrlKey || e.metaKey || e.altKey) return;
    if (target && ["INPUT", "TEXTAREA", "SELECT"].includes(target.tagName)) return;
    const go = (id) => { const link = document.getElementById(id); if (link) link.click(); };
    if (e.key === "j" || e.key === "ArrowRight") { e.preventDefault(); go("next"); }
    else if (e.key === "k" || e.key === "ArrowLeft") { e.preventDefault(); go("previous"); }
    else if (e.key === "c") { e.preventDefault(); document.getElementById("comment").focus(); }
    else if (/^[1-9]$/.test(e.key)) {
      const button = document.querySelector('button.apply[data-key="' + e.key + '"]');
      if (button) { e.preventDefault(); button.click(); }
    }
  });
})();
