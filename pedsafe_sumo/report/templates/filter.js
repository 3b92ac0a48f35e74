// Show the case rows whose data-* values match every filter chosen ("" = any), and count them.
(function () {
  var selects = document.querySelectorAll("#case-filters select");
  function apply() {
    var shown = 0;
    document.querySelectorAll("#cases tbody tr").forEach(function (row) {
      var match = Array.prototype.every.call(selects, function (s) {
        return !s.value || row.dataset[s.name] === s.value;
      });
      row.hidden = !match;
      if (match) { shown += 1; }
    });
    document.getElementById("cases-shown").textContent = shown;
  }
  selects.forEach(function (s) { s.addEventListener("change", apply); });
})();
