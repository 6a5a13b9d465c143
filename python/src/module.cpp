// avp._avp: avp from Python (docs/python.md). The pure-Python package python/avp/ wraps it.
#include <cmath>
#include <filesystem>
#include <string>

#include <fmt/format.h>
#include <pybind11/pybind11.h>

#include <avp/core/error.h>
#include <avp/experiment/registries.h>
#include <avp/zsl/register.h>

#include "bindings.h"

namespace avp::python {

void ThrowIfError(const Status& status) {
  if (status.ok()) return;
  const std::string message = status.ToString();
  switch (status.code()) {
    case StatusCode::kInvalidArgument:
    case StatusCode::kOutOfRange:
    case StatusCode::kParseError:
    case StatusCode::kUnreachable:
    case StatusCode::kNotFound:  // files are checked first (CheckFileExists)
      throw py::value_error(message);
    case StatusCode::kIoError:
      PyErr_SetString(PyExc_OSError, message.c_str());
      throw py::error_already_set();
    case StatusCode::kCancelled:
      PyErr_SetString(PyExc_KeyboardInterrupt, message.c_str());
      throw py::error_already_set();
    default:
      throw std::runtime_error(message);
  }
}

void CheckFileExists(const std::filesystem::path& path, std::string_view what) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    PyErr_SetString(PyExc_FileNotFoundError,
                    fmt::format("{} '{}' does not exist", what, path.string()).c_str());
    throw py::error_already_set();
  }
}

experiment::Registries& MutableProgramRegistries() {
  // Never destroyed: Python planners' factories outlive no interpreter.
  static auto* registries = [] {
    auto* r = new experiment::Registries(experiment::BuiltinRegistries());
    zsl::RegisterProgramSegmenters(r->segmenters);
    return r;
  }();
  return *registries;
}

const experiment::Registries& ProgramRegistries() { return MutableProgramRegistries(); }

std::string ShapeText(const py::array& a) {
  std::string text = "(";
  for (py::ssize_t i = 0; i < a.ndim(); ++i) {
    text += fmt::format("{}{}", i > 0 ? ", " : "", a.shape(i));
  }
  return text + (a.ndim() == 1 ? ",)" : ")");
}

namespace {

/// "float64": a dtype's name.
std::string DtypeName(const py::dtype& dtype) { return dtype.attr("name").cast<std::string>(); }

}  // namespace

py::array CheckedArray(const py::handle& value, std::string_view what, const py::dtype& dtype,
                       const std::vector<py::ssize_t>& shape) {
  if (!py::isinstance<py::array>(value)) {
    throw py::type_error(fmt::format("{}: expected a numpy array of {}, got {}", what,
                                     DtypeName(dtype),
                                     std::string(py::str(value.get_type().attr("__name__")))));
  }
  const auto a = py::reinterpret_borrow<py::array>(value);
  if (!a.dtype().equal(dtype)) {
    throw py::type_error(fmt::format("{}: dtype {}, expected {} (convert with .astype(np.{}))",
                                     what, DtypeName(a.dtype()), DtypeName(dtype),
                                     DtypeName(dtype)));
  }
  std::string expected = "(";
  bool matches = a.ndim() == static_cast<py::ssize_t>(shape.size());
  for (size_t i = 0; i < shape.size(); ++i) {
    expected +=
        fmt::format("{}{}", i > 0 ? ", " : "", shape[i] < 0 ? "n" : std::to_string(shape[i]));
    if (matches && shape[i] >= 0 && a.shape(static_cast<py::ssize_t>(i)) != shape[i]) {
      matches = false;
    }
  }
  expected += shape.size() == 1 ? ",)" : ")";
  if (!matches) {
    throw py::value_error(fmt::format("{}: shape {}, expected {}", what, ShapeText(a), expected));
  }
  if ((a.flags() & py::array::c_style) == 0) {
    throw py::value_error(
        fmt::format("{}: the array is not C-contiguous (a slice or a transpose?): pass "
                    "np.ascontiguousarray(...)",
                    what));
  }
  return a;
}

RigidTransform TransformFromArray(const py::handle& value, std::string_view what) {
  const py::array a = CheckedArray(value, what, py::dtype::of<double>(), {4, 4});
  const auto* d = static_cast<const double*>(a.data());
  Eigen::Matrix4d X;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) {
      X(r, c) = d[r * 4 + c];
      if (!std::isfinite(X(r, c))) {
        throw py::value_error(fmt::format("{}: element [{}, {}] is {}", what, r, c, X(r, c)));
      }
    }
  }
  const Eigen::Matrix3d R = X.topLeftCorner<3, 3>();
  if (!IsRotationMatrix(R, 1e-6) || X.row(3) != Eigen::RowVector4d(0, 0, 0, 1)) {
    throw py::value_error(fmt::format(
        "{}: not a rigid transform (the rotation must be orthonormal with determinant +1 within "
        "1e-6, the last row 0 0 0 1)",
        what));
  }
  return RigidTransform(R, X.topRightCorner<3, 1>());
}

py::array_t<double> TransformToArray(const RigidTransform& X) {
  const Eigen::Matrix4d M = X.ToMatrix4();
  std::vector<double> values(16);
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) values[r * 4 + c] = M(r, c);
  }
  return OwnedMatrix(std::move(values), 4);
}

py::array_t<double> BoxArray(const Box3& b) {
  return OwnedMatrix(std::vector<double>{b.min().x(), b.min().y(), b.min().z(), b.max().x(),
                                         b.max().y(), b.max().z()},
                     3);
}

}  // namespace avp::python

PYBIND11_MODULE(_avp, m) {
  m.doc() = "avp: active vision for agricultural robots (the compiled part; import avp)";
  namespace py = pybind11;
  // A violated precondition inside avp (avp::Error) is a bad value from the caller.
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const avp::Error& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    }
  });
  avp::python::BindMaps(m);
  avp::python::BindSimulation(m);
  avp::python::BindRuns(m);
  avp::python::BindPlanners(m);
  avp::python::BindRecordings(m);
}
