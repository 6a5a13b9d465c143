// Shared by the binding files of avp's Python module (python/src/*.cpp): errors as Python
// exceptions, arrays in and out, the program's registries. Internal to python/.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <avp/core/box.h>
#include <avp/core/status.h>
#include <avp/core/transform.h>
#include <avp/experiment/registries.h>
#include <avp/mapping/map_reader.h>

namespace avp::python {

namespace py = pybind11;

/// Raises `status` as the Python exception its code stands for: ValueError (invalid argument,
/// out of range, parse error, unreachable, not found: an unknown name), OSError (I/O),
/// KeyboardInterrupt (cancelled), RuntimeError (the others); the message is avp's, naming the
/// bad value. Does nothing for OK.
void ThrowIfError(const Status& status);

/// FileNotFoundError naming `what` and `path` when nothing is there.
void CheckFileExists(const std::filesystem::path& path, std::string_view what);

/// The value of `result`, or its error raised (ThrowIfError).
template <typename T>
T Unwrap(Result<T> result) {
  ThrowIfError(result.status());
  return std::move(*result);
}

/// The registries every avp program has (the built-ins, remote://, ywes, lsam), built once, and
/// the planners registered from Python (avp.register_planner: MutableProgramRegistries, with the
/// GIL held, never while a run or bench reads them).
const experiment::Registries& ProgramRegistries();
experiment::Registries& MutableProgramRegistries();

/// A 1-D array that owns `values` (moved into a capsule: no copy).
template <typename T>
py::array_t<T> OwnedArray(std::vector<T>&& values) {
  auto* owned = new std::vector<T>(std::move(values));
  py::capsule base(owned, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  using Shape = std::vector<py::ssize_t>;
  return py::array_t<T>(Shape{static_cast<py::ssize_t>(owned->size())},
                        Shape{static_cast<py::ssize_t>(sizeof(T))}, owned->data(), base);
}

/// An (n, cols) C-ordered array that owns `values` (n * cols of them, row-major).
template <typename T>
py::array_t<T> OwnedMatrix(std::vector<T>&& values, size_t cols) {
  auto* owned = new std::vector<T>(std::move(values));
  py::capsule base(owned, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  const auto rows = static_cast<py::ssize_t>(cols == 0 ? 0 : owned->size() / cols);
  using Shape = std::vector<py::ssize_t>;
  return py::array_t<T>(
      Shape{rows, static_cast<py::ssize_t>(cols)},
      Shape{static_cast<py::ssize_t>(cols * sizeof(T)), static_cast<py::ssize_t>(sizeof(T))},
      owned->data(), base);
}

/// An array that owns `image` (moved into a capsule: no copy): (height, width) for one channel,
/// (height, width, channels) otherwise.
template <typename Image>
py::array_t<typename Image::value_type> ImageArray(Image&& image) {
  using T = typename Image::value_type;
  auto* owned = new Image(std::move(image));
  py::capsule base(owned, [](void* p) { delete static_cast<Image*>(p); });
  const auto h = static_cast<py::ssize_t>(owned->height());
  const auto w = static_cast<py::ssize_t>(owned->width());
  const auto c = static_cast<py::ssize_t>(Image::channels);
  const auto t = static_cast<py::ssize_t>(sizeof(T));
  using Shape = std::vector<py::ssize_t>;
  if (c == 1) return py::array_t<T>(Shape{h, w}, Shape{w * t, t}, owned->data().data(), base);
  return py::array_t<T>(Shape{h, w, c}, Shape{w * c * t, c * t, t}, owned->data().data(), base);
}

/// "(480, 640, 3)": a shape for messages.
std::string ShapeText(const py::array& a);

/// An array argument checked without conversion (no silent copy, no silent cast): a numpy array
/// (TypeError otherwise), of dtype `dtype` exactly (TypeError naming `what`, the dtype given and
/// the one expected), C-contiguous (ValueError: np.ascontiguousarray), of `shape` (-1: any size;
/// ValueError naming both shapes).
py::array CheckedArray(const py::handle& value, std::string_view what, const py::dtype& dtype,
                       const std::vector<py::ssize_t>& shape);

/// A rigid transform from a 4x4 float64 array (rotation orthonormal, last row 0 0 0 1; ValueError
/// otherwise) and back.
RigidTransform TransformFromArray(const py::handle& value, std::string_view what);
py::array_t<double> TransformToArray(const RigidTransform& X);

/// A box as [[min x, y, z], [max x, y, z]] (2x3 float64).
py::array_t<double> BoxArray(const Box3& box);

/// avp.Map: a map read from a file (owned), or the map a Python planner is handed for the length
/// of its call (borrowed: using it afterwards raises RuntimeError).
class PyMap {
 public:
  explicit PyMap(std::shared_ptr<const mapping::LoadedMap> loaded)
      : loaded_(std::move(loaded)), map_(&loaded_->map), source_(loaded_->source) {}
  PyMap(const mapping::SemanticMap& borrowed, std::shared_ptr<const bool> alive)
      : map_(&borrowed), alive_(std::move(alive)) {}

  /// The map. @throws std::runtime_error when it was borrowed and the call is over.
  const mapping::SemanticMap& map() const;
  /// Where it came from (format, path: empty for a borrowed one).
  const mapping::MapSource& source() const { return source_; }
  bool borrowed() const { return loaded_ == nullptr; }

 private:
  std::shared_ptr<const mapping::LoadedMap> loaded_;
  const mapping::SemanticMap* map_ = nullptr;
  mapping::MapSource source_;
  std::shared_ptr<const bool> alive_;
};

/// The module's parts, one per file.
void BindMaps(py::module_& m);
void BindSimulation(py::module_& m);
void BindRuns(py::module_& m);
void BindPlanners(py::module_& m);
void BindRecordings(py::module_& m);

}  // namespace avp::python
