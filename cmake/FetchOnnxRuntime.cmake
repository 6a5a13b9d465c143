# Fetches ONNX Runtime from the npm registry into a per-user cache (docs/zero-shot-models.md §3).
#
#   cmake [-DAVP_ORT_GPU=1] [-DAVP_ORT_CHECK=1] [-DAVP_ORT_CACHE=<dir>] \
#         -P cmake/FetchOnnxRuntime.cmake
#
# (scripts/onnxruntime wraps this; scripts/setup calls it.) The packages, their npm integrity and
# every extracted member's sha256 come from cmake/onnxruntime.lock. Steps:
#   1. `npm pack <name>@<version>` (runs no scripts) into the cache:
#      ${XDG_CACHE_HOME:-~/.cache}/avp/npm, or AVP_ORT_CACHE (a -D variable or the environment
#      variable of that name).
#   2. Check the tarball's SHA-512 against the lock; a mismatch stops and names the package.
#   3. Extract only the lock's members (headers, .so files), check each one's sha256, and lay them
#      out as <cache>/onnxruntime-<ver>/{include,lib}: the core as lib/libonnxruntime.so.1 (its
#      SONAME) with a lib/libonnxruntime.so link, the provider libraries beside it (ORT loads them
#      from there).
#   4. Write <tree>/avp-ort.stamp. A later run whose stamp and file sizes match does no network
#      access and no hashing: it prints that the tree is up to date.
# The GPU package (CUDA and TensorRT execution providers) is fetched only with AVP_ORT_GPU=1 (a -D
# variable or the environment); once installed it is kept by later runs without it.
# AVP_ORT_CHECK=1 only checks that the tree is present and up to date (exit status 1 otherwise).
#
# Included from CMake (cmake/AvpOnnxRuntime.cmake) this file only defines the functions below.

cmake_minimum_required(VERSION 3.25)

set(AVP_ORT_LOCK_FILE "${CMAKE_CURRENT_LIST_DIR}/onnxruntime.lock")
set(AVP_ORT_STAMP_NAME "avp-ort.stamp")

# The per-user cache directory: AVP_ORT_CACHE (variable, then environment), else
# ${XDG_CACHE_HOME:-$HOME/.cache}/avp/npm.
function(avp_ort_cache_dir out)
  if(AVP_ORT_CACHE)
    set(dir "${AVP_ORT_CACHE}")
  elseif(DEFINED ENV{AVP_ORT_CACHE} AND NOT "$ENV{AVP_ORT_CACHE}" STREQUAL "")
    set(dir "$ENV{AVP_ORT_CACHE}")
  elseif(DEFINED ENV{XDG_CACHE_HOME} AND NOT "$ENV{XDG_CACHE_HOME}" STREQUAL "")
    set(dir "$ENV{XDG_CACHE_HOME}/avp/npm")
  elseif(DEFINED ENV{HOME} AND NOT "$ENV{HOME}" STREQUAL "")
    set(dir "$ENV{HOME}/.cache/avp/npm")
  else()
    message(FATAL_ERROR "onnxruntime: neither HOME nor XDG_CACHE_HOME is set; set AVP_ORT_CACHE")
  endif()
  file(TO_CMAKE_PATH "${dir}" dir)
  set(${out} "${dir}" PARENT_SCOPE)
endfunction()

# The ONNX Runtime version the lock pins (for example 1.29.0).
function(avp_ort_lock_version out)
  file(READ "${AVP_ORT_LOCK_FILE}" lock)
  string(JSON version GET "${lock}" onnxruntime_version)
  set(${out} "${version}" PARENT_SCOPE)
endfunction()

# The default extracted tree: <cache>/onnxruntime-<version>.
function(avp_ort_default_root out)
  avp_ort_cache_dir(cache)
  avp_ort_lock_version(version)
  set(${out} "${cache}/onnxruntime-${version}" PARENT_SCOPE)
endfunction()

# Decodes base64 (an npm integrity digest) to lower-case hex.
function(_avp_ort_base64_to_hex b64 out)
  set(alphabet "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/")
  set(hexdigits "0123456789abcdef")
  string(REGEX REPLACE "=+$" "" s "${b64}")
  string(LENGTH "${s}" n)
  set(hex "")
  set(bits 0)
  set(nbits 0)
  math(EXPR last "${n} - 1")
  foreach(i RANGE 0 ${last})
    string(SUBSTRING "${s}" ${i} 1 c)
    string(FIND "${alphabet}" "${c}" v)
    if(v LESS 0)
      message(FATAL_ERROR "onnxruntime: '${b64}' is not base64 (character '${c}')")
    endif()
    math(EXPR bits "((${bits} << 6) | ${v}) & 0xFFFF")
    math(EXPR nbits "${nbits} + 6")
    if(nbits GREATER_EQUAL 8)
      math(EXPR nbits "${nbits} - 8")
      math(EXPR hi "(${bits} >> (${nbits} + 4)) & 15")
      math(EXPR lo "(${bits} >> ${nbits}) & 15")
      string(SUBSTRING "${hexdigits}" ${hi} 1 h)
      string(SUBSTRING "${hexdigits}" ${lo} 1 l)
      string(APPEND hex "${h}${l}")
    endif()
  endforeach()
  set(${out} "${hex}" PARENT_SCOPE)
endfunction()

# Reads package <index> of the lock into
# <prefix>_{NAME,VERSION,INTEGRITY,OPTIONAL,ENABLED_BY,MEMBERS} (MEMBERS: the number of members).
function(_avp_ort_package lock index prefix)
  foreach(field name version integrity optional enabled_by)
    string(JSON value GET "${lock}" packages ${index} ${field})
    string(TOUPPER "${field}" upper)
    set(${prefix}_${upper} "${value}" PARENT_SCOPE)
  endforeach()
  string(JSON count LENGTH "${lock}" packages ${index} members)
  set(${prefix}_MEMBERS ${count} PARENT_SCOPE)
endfunction()

# Lines of the stamp ("<name> <version> <integrity>"), or empty when there is none.
function(_avp_ort_read_stamp root out)
  set(lines "")
  if(EXISTS "${root}/${AVP_ORT_STAMP_NAME}")
    file(STRINGS "${root}/${AVP_ORT_STAMP_NAME}" lines REGEX "^[^#]")
  endif()
  set(${out} "${lines}" PARENT_SCOPE)
endfunction()

# Checks the tree at <root> against the lock without hashing: the stamp lists every package in
# <wanted> (indices into the lock's packages) with the lock's integrity, and every member of every
# stamped package has the size the lock gives. Sets <ok> TRUE/FALSE and <reason>, and <installed> to
# the lock indices of the packages the stamp lists with the current integrity.
function(avp_ort_check_tree root wanted ok reason installed)
  file(READ "${AVP_ORT_LOCK_FILE}" lock)
  string(JSON npkg LENGTH "${lock}" packages)
  math(EXPR lastpkg "${npkg} - 1")
  _avp_ort_read_stamp("${root}" stamp)
  set(present "")
  foreach(p RANGE 0 ${lastpkg})
    _avp_ort_package("${lock}" ${p} P)
    if("${P_NAME} ${P_VERSION} ${P_INTEGRITY}" IN_LIST stamp)
      list(APPEND present ${p})
    endif()
  endforeach()
  set(${installed} "${present}" PARENT_SCOPE)
  if(NOT EXISTS "${root}/${AVP_ORT_STAMP_NAME}")
    set(${ok} FALSE PARENT_SCOPE)
    set(${reason} "${root} is not set up (no ${AVP_ORT_STAMP_NAME})" PARENT_SCOPE)
    return()
  endif()
  foreach(p IN LISTS wanted)
    if(NOT p IN_LIST present)
      _avp_ort_package("${lock}" ${p} P)
      set(${ok} FALSE PARENT_SCOPE)
      set(${reason} "${P_NAME}@${P_VERSION} (as in the lock) is not installed in ${root}"
          PARENT_SCOPE)
      return()
    endif()
  endforeach()
  # Expected size of each destination: the last installed package naming it wins.
  set(dests "")
  foreach(p IN LISTS present)
    _avp_ort_package("${lock}" ${p} P)
    math(EXPR lastm "${P_MEMBERS} - 1")
    foreach(m RANGE 0 ${lastm})
      string(JSON dest GET "${lock}" packages ${p} members ${m} dest)
      string(JSON bytes GET "${lock}" packages ${p} members ${m} bytes)
      string(MAKE_C_IDENTIFIER "${dest}" key)
      if(NOT key IN_LIST dests)
        list(APPEND dests ${key})
      endif()
      set(_dest_${key} "${dest}")
      set(_bytes_${key} "${bytes}")
    endforeach()
  endforeach()
  foreach(key IN LISTS dests)
    set(file "${root}/${_dest_${key}}")
    if(NOT EXISTS "${file}")
      set(${ok} FALSE PARENT_SCOPE)
      set(${reason} "${file} is missing" PARENT_SCOPE)
      return()
    endif()
    file(SIZE "${file}" size)
    if(NOT size EQUAL _bytes_${key})
      set(${ok} FALSE PARENT_SCOPE)
      set(${reason} "${file} has ${size} bytes; the lock says ${_bytes_${key}}" PARENT_SCOPE)
      return()
    endif()
  endforeach()
  string(JSON nlinks LENGTH "${lock}" links)
  math(EXPR lastl "${nlinks} - 1")
  foreach(l RANGE 0 ${lastl})
    string(JSON name GET "${lock}" links ${l} name)
    if(NOT IS_SYMLINK "${root}/${name}")
      set(${ok} FALSE PARENT_SCOPE)
      set(${reason} "${root}/${name} is not a symbolic link" PARENT_SCOPE)
      return()
    endif()
  endforeach()
  set(${ok} TRUE PARENT_SCOPE)
  set(${reason} "" PARENT_SCOPE)
endfunction()

# Checks <file>'s SHA-512 against an npm integrity string; sets <ok> and <actual> (base16).
function(_avp_ort_check_integrity file integrity ok actual)
  if(NOT integrity MATCHES "^sha512-(.+)$")
    message(FATAL_ERROR "onnxruntime: lock integrity '${integrity}' is not a sha512- digest")
  endif()
  _avp_ort_base64_to_hex("${CMAKE_MATCH_1}" expected)
  file(SHA512 "${file}" digest)
  if(digest STREQUAL expected)
    set(${ok} TRUE PARENT_SCOPE)
  else()
    set(${ok} FALSE PARENT_SCOPE)
  endif()
  set(${actual} "${digest}" PARENT_SCOPE)
endfunction()

# Makes sure <cache>/<name>-<version>.tgz is there with the lock's integrity: a cached tarball that
# does not match is removed and fetched again; a fetched one that does not match is an error.
function(_avp_ort_tarball cache name version integrity out)
  set(tgz "${cache}/${name}-${version}.tgz")
  if(EXISTS "${tgz}")
    _avp_ort_check_integrity("${tgz}" "${integrity}" good digest)
    if(good)
      set(${out} "${tgz}" PARENT_SCOPE)
      return()
    endif()
    message(WARNING "onnxruntime: cached ${tgz} does not match the lock (sha512 ${digest}); "
                    "fetching it again")
    file(REMOVE "${tgz}")
  endif()
  find_program(AVP_NPM npm)
  if(NOT AVP_NPM)
    message(FATAL_ERROR
            "onnxruntime: npm not found; run scripts/setup (it installs nodejs and npm)")
  endif()
  string(RANDOM LENGTH 8 tag)
  set(dl "${cache}/.download-${tag}")
  file(MAKE_DIRECTORY "${dl}")
  message(STATUS "onnxruntime: fetching ${name}@${version} from the npm registry")
  # npm's own cache goes to the scratch folder too, so the tarball is not stored twice.
  execute_process(
    COMMAND "${AVP_NPM}" pack "${name}@${version}" --pack-destination "${dl}" --cache "${dl}/cache"
            --ignore-scripts --loglevel=error --no-update-notifier --no-fund --no-audit
    WORKING_DIRECTORY "${dl}"
    RESULT_VARIABLE rc
    OUTPUT_VARIABLE npm_out
    ERROR_VARIABLE npm_err)
  file(GLOB packed "${dl}/*.tgz")
  list(LENGTH packed npacked)
  if(NOT rc EQUAL 0 OR NOT npacked EQUAL 1)
    file(REMOVE_RECURSE "${dl}")
    string(STRIP "${npm_err}" npm_err)
    message(FATAL_ERROR
            "onnxruntime: `npm pack ${name}@${version}` failed (exit ${rc}): ${npm_err}\n"
            "Is the npm registry reachable? Or configure with -DAVP_WITH_ONNX=OFF.")
  endif()
  _avp_ort_check_integrity("${packed}" "${integrity}" good digest)
  if(NOT good)
    file(REMOVE_RECURSE "${dl}")
    message(FATAL_ERROR "onnxruntime: ${name}@${version} from the registry does not match "
                        "cmake/onnxruntime.lock: its sha512 is ${digest}, the lock's integrity is "
                        "${integrity}")
  endif()
  file(RENAME "${packed}" "${tgz}")
  file(REMOVE_RECURSE "${dl}")
  set(${out} "${tgz}" PARENT_SCOPE)
endfunction()

# Extracts package <p>'s members from <tgz> into <tree>, checking each one's sha256.
function(_avp_ort_extract lock p tgz tree)
  _avp_ort_package("${lock}" ${p} P)
  math(EXPR lastm "${P_MEMBERS} - 1")
  set(patterns "")
  foreach(m RANGE 0 ${lastm})
    string(JSON path GET "${lock}" packages ${p} members ${m} path)
    list(APPEND patterns "${path}")
  endforeach()
  set(x "${tree}/.x-${p}")
  file(REMOVE_RECURSE "${x}")
  file(ARCHIVE_EXTRACT INPUT "${tgz}" DESTINATION "${x}" PATTERNS ${patterns})
  foreach(m RANGE 0 ${lastm})
    string(JSON path GET "${lock}" packages ${p} members ${m} path)
    string(JSON dest GET "${lock}" packages ${p} members ${m} dest)
    string(JSON sha256 GET "${lock}" packages ${p} members ${m} sha256)
    if(NOT EXISTS "${x}/${path}")
      message(FATAL_ERROR "onnxruntime: ${P_NAME}@${P_VERSION} has no member ${path}")
    endif()
    file(SHA256 "${x}/${path}" digest)
    if(NOT digest STREQUAL sha256)
      message(FATAL_ERROR "onnxruntime: ${P_NAME}@${P_VERSION} member ${path} has sha256 "
                          "${digest}; cmake/onnxruntime.lock says ${sha256}")
    endif()
    get_filename_component(dir "${tree}/${dest}" DIRECTORY)
    file(MAKE_DIRECTORY "${dir}")
    file(RENAME "${x}/${path}" "${tree}/${dest}")
  endforeach()
  file(REMOVE_RECURSE "${x}")
endfunction()

function(_avp_ort_truthy value out)
  if(value MATCHES "^(1|ON|on|On|YES|yes|TRUE|true|Y|y)$")
    set(${out} TRUE PARENT_SCOPE)
  else()
    set(${out} FALSE PARENT_SCOPE)
  endif()
endfunction()

function(avp_ort_main)
  string(TIMESTAMP t0 "%s")
  file(READ "${AVP_ORT_LOCK_FILE}" lock)
  avp_ort_cache_dir(cache)
  avp_ort_default_root(root)
  set(gpu "${AVP_ORT_GPU}")
  if("${gpu}" STREQUAL "" AND DEFINED ENV{AVP_ORT_GPU})
    set(gpu "$ENV{AVP_ORT_GPU}")
  endif()
  _avp_ort_truthy("${gpu}" gpu)
  _avp_ort_truthy("${AVP_ORT_CHECK}" check_only)

  # Wanted: every required package, plus the optional ones their switch enables.
  string(JSON npkg LENGTH "${lock}" packages)
  math(EXPR lastpkg "${npkg} - 1")
  set(wanted "")
  foreach(p RANGE 0 ${lastpkg})
    _avp_ort_package("${lock}" ${p} P)
    if(NOT P_OPTIONAL OR (P_ENABLED_BY STREQUAL "AVP_ORT_GPU" AND gpu))
      list(APPEND wanted ${p})
    endif()
  endforeach()

  if(NOT check_only)
    file(MAKE_DIRECTORY "${cache}")
    # One fetch at a time per cache (two configures, two engineers).
    file(LOCK "${cache}/.lock" GUARD FUNCTION TIMEOUT 1800 RESULT_VARIABLE lock_rc)
    if(NOT lock_rc STREQUAL "0")
      message(FATAL_ERROR "onnxruntime: could not lock ${cache}/.lock: ${lock_rc}")
    endif()
  endif()

  avp_ort_check_tree("${root}" "${wanted}" ok reason installed)
  set(names "")
  foreach(p IN LISTS wanted installed)
    _avp_ort_package("${lock}" ${p} P)
    list(APPEND names "${P_NAME}@${P_VERSION}")
  endforeach()
  list(REMOVE_DUPLICATES names)
  list(JOIN names ", " names)
  if(ok)
    message(STATUS "onnxruntime: ${root} is up to date (${names})")
    return()
  endif()
  if(check_only)
    message(FATAL_ERROR "onnxruntime: ${reason}; run scripts/setup (or scripts/onnxruntime), "
                        "or configure with -DAVP_WITH_ONNX=OFF")
  endif()

  # Rebuild the whole tree in a staging folder, then swap it in: a half-written tree is never used.
  set(keep ${wanted} ${installed})
  list(REMOVE_DUPLICATES keep)
  list(SORT keep COMPARE NATURAL)
  set(stage "${cache}/.onnxruntime-staging")
  file(REMOVE_RECURSE "${stage}")
  file(MAKE_DIRECTORY "${stage}/include" "${stage}/lib")
  set(stamp "# written by cmake/FetchOnnxRuntime.cmake from cmake/onnxruntime.lock\n")
  foreach(p IN LISTS keep)
    _avp_ort_package("${lock}" ${p} P)
    _avp_ort_tarball("${cache}" "${P_NAME}" "${P_VERSION}" "${P_INTEGRITY}" tgz)
    message(STATUS "onnxruntime: extracting ${P_NAME}@${P_VERSION}")
    _avp_ort_extract("${lock}" ${p} "${tgz}" "${stage}")
    string(APPEND stamp "${P_NAME} ${P_VERSION} ${P_INTEGRITY}\n")
  endforeach()
  string(JSON nlinks LENGTH "${lock}" links)
  math(EXPR lastl "${nlinks} - 1")
  foreach(l RANGE 0 ${lastl})
    string(JSON name GET "${lock}" links ${l} name)
    string(JSON target GET "${lock}" links ${l} target)
    file(CREATE_LINK "${target}" "${stage}/${name}" SYMBOLIC)
  endforeach()
  file(WRITE "${stage}/${AVP_ORT_STAMP_NAME}" "${stamp}")
  if(EXISTS "${root}")
    file(REMOVE_RECURSE "${root}.old")
    file(RENAME "${root}" "${root}.old")
  endif()
  file(RENAME "${stage}" "${root}")
  file(REMOVE_RECURSE "${root}.old")
  string(TIMESTAMP t1 "%s")
  math(EXPR dt "${t1} - ${t0}")
  message(STATUS "onnxruntime: installed ${names} into ${root} in ${dt} s")
endfunction()

if(CMAKE_SCRIPT_MODE_FILE STREQUAL CMAKE_CURRENT_LIST_FILE)
  avp_ort_main()
endif()
