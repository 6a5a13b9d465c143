#pragma once

// The report pages' scripts, bundled at build time (cmake/AvpReportWeb.cmake): esbuild bundles
// report/web/src/run.js and report/web/src/bench.js with three.js (pinned in
// report/web/package-lock.json) into one minified IIFE script each, three.js's licence kept at the
// end. report.html inlines them in a <script> element; neither contains "</script".

#include <string_view>

namespace avp::report {

// The run report's viewer (report/web/src/run.js and what it imports).
std::string_view RunViewerJs();
// The bench report's page script (report/web/src/bench.js and what it imports).
std::string_view BenchViewerJs();

}  // namespace avp::report
