# The report pages' JavaScript (report.html of avp run / avp bench; docs/report.md "How the report
# is built and tested"). Included by report/CMakeLists.txt. Nothing is downloaded here:
# scripts/setup installs report/web/package-lock.json (three.js, esbuild; pinned with integrity)
# with `npm ci` into ${XDG_CACHE_HOME:-~/.cache}/avp/npm-report/<sha256 of the lockfile>/; this file
# finds that folder at configure time. At build time esbuild bundles each entry of report/web/src
# (run.js, bench.js) into one IIFE script, and cmake/AvpEmbedWebAssets.cmake embeds the bundles in
# a generated C++ source behind avp/report/web_assets.h (RunViewerJs(), BenchViewerJs()).
#
# Defines:
#   AVP_REPORT_NPM_DIR   cache variable: the folder holding node_modules/ (empty: the one of the
#                        current lockfile; or the environment's AVP_NPM_REPORT_DIR)
#   avp_report_web_assets(<target>)   adds the generated web_assets.cpp to <target>

set(AVP_REPORT_WEB_DIR "${CMAKE_SOURCE_DIR}/report/web")
set(_avp_web_lock "${AVP_REPORT_WEB_DIR}/package-lock.json")
# Re-configure when the pins change: a new lockfile is a new folder.
set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS
             "${_avp_web_lock}" "${AVP_REPORT_WEB_DIR}/package.json")

set(AVP_REPORT_NPM_DIR "" CACHE PATH
    "Folder with node_modules/ of report/web/package-lock.json (empty: the one scripts/setup installs)")
if(AVP_REPORT_NPM_DIR)
  set(_avp_web_npm "${AVP_REPORT_NPM_DIR}")
elseif(DEFINED ENV{AVP_NPM_REPORT_DIR} AND NOT "$ENV{AVP_NPM_REPORT_DIR}" STREQUAL "")
  set(_avp_web_npm "$ENV{AVP_NPM_REPORT_DIR}")
else()
  if(DEFINED ENV{XDG_CACHE_HOME} AND NOT "$ENV{XDG_CACHE_HOME}" STREQUAL "")
    set(_avp_cache "$ENV{XDG_CACHE_HOME}")
  else()
    set(_avp_cache "$ENV{HOME}/.cache")
  endif()
  file(SHA256 "${_avp_web_lock}" _avp_web_lock_sha)
  set(_avp_web_npm "${_avp_cache}/avp/npm-report/${_avp_web_lock_sha}")
endif()

find_program(AVP_NODE_EXECUTABLE NAMES node nodejs)
if(NOT AVP_NODE_EXECUTABLE)
  message(FATAL_ERROR "report: node (Node.js) not found; it runs esbuild, which bundles the "
                      "report pages (report/web); run scripts/setup")
endif()
# .avp-installed is written by scripts/setup after a complete `npm ci`; esbuild's bin/esbuild (a
# node script) runs the native binary of the @esbuild/<platform> package npm installed with it.
foreach(_f node_modules/.avp-installed node_modules/three/package.json
           node_modules/esbuild/bin/esbuild)
  if(NOT EXISTS "${_avp_web_npm}/${_f}")
    message(FATAL_ERROR "report: the report pages' npm packages (report/web/package-lock.json: "
                        "three, esbuild) are not installed: ${_avp_web_npm}/${_f} is missing; "
                        "run scripts/setup (it installs them there, offline once cached)")
  endif()
endforeach()
set(_avp_esbuild "${_avp_web_npm}/node_modules/esbuild/bin/esbuild")
message(STATUS "Report web packages: ${_avp_web_npm}")

# Everything esbuild may read: a new module under report/web/src is picked up without editing this
# file (CONFIGURE_DEPENDS re-globs at each build). The lockfile pins three and esbuild.
file(GLOB_RECURSE _avp_web_sources CONFIGURE_DEPENDS "${AVP_REPORT_WEB_DIR}/src/*")
set(_avp_web_out "${CMAKE_CURRENT_BINARY_DIR}/web")

function(avp_report_web_assets target)
  set(bundles "")
  set(pairs "")
  # <entry in report/web/src>:<C++ function returning its bundle>
  foreach(entry run:RunViewerJs bench:BenchViewerJs)
    string(REPLACE ":" ";" entry "${entry}")
    list(GET entry 0 name)
    list(GET entry 1 function)
    set(bundle "${_avp_web_out}/${name}.js")
    # IIFE for an inline <script>; ES2020 for any browser of the last years; minified, with the
    # licence comments of what is bundled (three.js's @license) gathered at the end; output
    # depends only on the sources and the pinned packages (no paths, no time, no source map).
    # NODE_PATH lets `import "three"` resolve from the installed node_modules outside the tree.
    add_custom_command(
      OUTPUT "${bundle}"
      COMMAND "${CMAKE_COMMAND}" -E env "NODE_PATH=${_avp_web_npm}/node_modules"
              "${AVP_NODE_EXECUTABLE}" "${_avp_esbuild}" "src/${name}.js" --bundle --format=iife
              --minify --target=es2020 --legal-comments=eof --charset=ascii --log-level=warning
              "--outfile=${bundle}"
      DEPENDS ${_avp_web_sources} "${_avp_web_lock}"
      WORKING_DIRECTORY "${AVP_REPORT_WEB_DIR}"
      COMMENT "esbuild: bundling report/web/src/${name}.js"
      VERBATIM)
    list(APPEND bundles "${bundle}")
    list(APPEND pairs "${function}=${bundle}")
  endforeach()
  set(cpp "${_avp_web_out}/web_assets.cpp")
  add_custom_command(
    OUTPUT "${cpp}"
    COMMAND "${CMAKE_COMMAND}" "-DOUT=${cpp}" "-DASSETS=${pairs}"
            -P "${CMAKE_SOURCE_DIR}/cmake/AvpEmbedWebAssets.cmake"
    DEPENDS ${bundles} "${CMAKE_SOURCE_DIR}/cmake/AvpEmbedWebAssets.cmake"
    COMMENT "Embedding the report pages' scripts in web_assets.cpp"
    VERBATIM)
  target_sources(${target} PRIVATE "${cpp}")
endfunction()
