// Live status of an attempt and drag-and-drop upload. No framework, nothing remote.
"use strict";
(function () {
  const card = document.getElementById("status-card");
  if (card) {
    const url = card.dataset.statusUrl;
    const show = (view) => {
      document.getElementById("status").textContent = view.status;
      if (view.score !== null) {
        let text = "Score: " + view.score + " / " + view.max_score;
        if (view.penalty > 0) text += " (before the late penalty " + view.raw_score + ")";
        document.getElementById("score").textContent = text;
      }
      document.getElementById("message").textContent = view.message || "";
      if (view.feedback_url) document.getElementById("feedback-link").hidden = false;
      return view.status === "queued" || view.status === "running";
    };
    // ?wait=20: the service answers once the attempt is graded (or after 20 s)
    const poll = () => {
      const asked = Date.now();
      fetch(url + "?wait=20", {headers: {"Accept": "application/json"}, credentials: "same-origin"})
        .then((r) => r.json())
        .then((view) => { if (show(view)) setTimeout(poll, Math.max(0, 700 - (Date.now() - asked))); })
        .catch(() => setTimeout(poll, 2000));
    };
    if (["queued", "running"].includes(document.getElementById("status").textContent)) poll();
  }
  const zone = document.getElementById("upload");
  if (zone) {
    const input = document.getElementById("notebook");
    zone.addEventListener("dragover", (e) => { e.preventDefault(); zone.classList.add("over"); });
    zone.addEventListener("dragleave", () => zone.classList.remove("over"));
    zone.addEventListener("drop", (e) => {
      e.preventDefault();
      zone.classList.remove("over");
      if (e.dataTransfer.files.length) { input.files = e.dataTransfer.files; zone.requestSubmit(); }
    });
  }
})();
