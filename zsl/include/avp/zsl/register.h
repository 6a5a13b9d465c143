#pragma once

#include <filesystem>
#include <string_view>

#include <avp/core/status.h>
#include <avp/segmentation/segmenter_registry.h>

namespace avp::zsl {

/// Registers the zero-shot backends with `registry` (and so with every command and config that
/// takes a segmenter spec):
///   "ywes", "lsam"                 the model directory from AVP_ZSL_MODEL_DIR;
///   "ywes://DIR", "lsam://DIR"     the model directory DIR ("ywes:///abs/models",
///                                  "ywes://relative/models").
/// Sessions use the device of AVP_ZSL_DEVICE (auto, cpu, cuda) and ORT's default thread count;
/// with AVP_ZSL_MODEL_SERVER=grpc://HOST:PORT the networks run on that KServe v2 server instead
/// (`avp serve models`, Triton; RuntimeOptions::model_server), the manifest still read from DIR;
/// every other setting is YwesOptions{} / LsamOptions{} (the reference values). The seed is
/// ignored (the backends are deterministic).
///
/// Errors the factories return: FailedPrecondition when the spec names no directory and
/// AVP_ZSL_MODEL_DIR is unset, saying what to set and what the folder must hold
/// (docs/zero-shot-models.md); the Create errors of the backends (NotFound for a missing
/// directory or model, InvalidArgument for a wrong contract, ...); in a build without ONNX
/// Runtime (AVP_WITH_ONNX off), FailedPrecondition saying so. They have no options table: their
/// settings come from the manifest (docs/zero-shot-models.md). @throws avp::Error if a name is
/// already taken.
void RegisterZslSegmenters(segmentation::SegmenterRegistry& registry);

/// The model directory a "ywes"/"lsam" spec names: DIR for "<backend>://DIR", else
/// AVP_ZSL_MODEL_DIR. Errors: FailedPrecondition (no directory, as above), InvalidArgument
/// (a spec of another backend, or "<backend>://" with nothing after it).
Result<std::filesystem::path> ModelDirForSpec(std::string_view backend, std::string_view spec);

}  // namespace avp::zsl
