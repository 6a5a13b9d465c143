#include "raw_sertype.h"

#include <cstring>
#include <functional>
#include <memory>
#include <new>
#include <vector>

#include <dds/ddsi/ddsi_serdata.h>
#include <dds/ddsi/ddsi_sertype.h>
#include <dds/ddsi/q_radmin.h>

namespace avp::ros::dds::internal {
namespace {

struct RawSertype : ddsi_sertype {};

// Bytes are kept padded with zeros to a multiple of 4: Cyclone may ask to_ser / to_ser_ref for
// up to alignup4(size) bytes.
struct RawSerdata : ddsi_serdata {
  std::vector<uint8_t> bytes;
  size_t size = 0;

  void Resize(size_t n) {
    size = n;
    bytes.assign((n + 3) & ~size_t{3}, 0);
  }
};

RawSerdata* NewSerdata(const ddsi_sertype* type, ddsi_serdata_kind kind) {
  auto* d = new (std::nothrow) RawSerdata();
  if (d == nullptr) return nullptr;
  ddsi_serdata_init(d, type, kind);
  return d;
}

// ---- serdata ops
// ---------------------------------------------------------------------------------
bool SerdataEqKey(const ddsi_serdata*, const ddsi_serdata*) { return true; }  // keyless

uint32_t SerdataSize(const ddsi_serdata* d) {
  return static_cast<uint32_t>(static_cast<const RawSerdata*>(d)->size);
}

void SerdataFree(ddsi_serdata* d) { delete static_cast<RawSerdata*>(d); }

ddsi_serdata* SerdataFromSer(const ddsi_sertype* type, ddsi_serdata_kind kind,
                             const nn_rdata* fragchain, size_t size) {
  RawSerdata* d = NewSerdata(type, kind);
  if (d == nullptr) return nullptr;
  d->Resize(size);
  uint32_t off = 0;
  // Fragments arrive in order and may overlap; copy only what each one adds.
  while (fragchain != nullptr) {
    if (fragchain->maxp1 > off) {
      const unsigned char* payload =
          NN_RMSG_PAYLOADOFF(fragchain->rmsg, NN_RDATA_PAYLOAD_OFF(fragchain));
      const size_t n = std::min<size_t>(fragchain->maxp1, size) - off;
      std::memcpy(d->bytes.data() + off, payload + off - fragchain->min, n);
      off = fragchain->maxp1;
    }
    fragchain = fragchain->nextfrag;
  }
  return d;
}

ddsi_serdata* SerdataFromSerIov(const ddsi_sertype* type, ddsi_serdata_kind kind,
                                ddsrt_msg_iovlen_t niov, const ddsrt_iovec_t* iov, size_t size) {
  RawSerdata* d = NewSerdata(type, kind);
  if (d == nullptr) return nullptr;
  d->Resize(size);
  size_t off = 0;
  for (ddsrt_msg_iovlen_t i = 0; i < niov && off < size; ++i) {
    const size_t n = std::min<size_t>(iov[i].iov_len, size - off);
    std::memcpy(d->bytes.data() + off, iov[i].iov_base, n);
    off += n;
  }
  return d;
}

ddsi_serdata* SerdataFromKeyhash(const ddsi_sertype* type, const ddsi_keyhash*) {
  return NewSerdata(type, SDK_KEY);
}

// A "sample" of this type is a RawSample: lets dds_write work too (not used by avp).
struct RawSample {
  const uint8_t* data;
  size_t size;
};

ddsi_serdata* SerdataFromSample(const ddsi_sertype* type, ddsi_serdata_kind kind,
                                const void* sample) {
  RawSerdata* d = NewSerdata(type, kind);
  if (d == nullptr || kind != SDK_DATA) return d;
  const auto* raw = static_cast<const RawSample*>(sample);
  d->Resize(raw->size);
  if (raw->size > 0) std::memcpy(d->bytes.data(), raw->data, raw->size);
  return d;
}

void SerdataToSer(const ddsi_serdata* d, size_t off, size_t sz, void* buf) {
  const auto* r = static_cast<const RawSerdata*>(d);
  if (off + sz <= r->bytes.size()) std::memcpy(buf, r->bytes.data() + off, sz);
}

ddsi_serdata* SerdataToSerRef(const ddsi_serdata* d, size_t off, size_t sz, ddsrt_iovec_t* ref) {
  const auto* r = static_cast<const RawSerdata*>(d);
  ref->iov_base = const_cast<uint8_t*>(r->bytes.data() + off);
  ref->iov_len = static_cast<ddsrt_iov_len_t>(sz);
  return ddsi_serdata_ref(d);
}

void SerdataToSerUnref(ddsi_serdata* d, const ddsrt_iovec_t*) { ddsi_serdata_unref(d); }

bool SerdataToSample(const ddsi_serdata* d, void* sample, void**, void*) {
  const auto* r = static_cast<const RawSerdata*>(d);
  auto* raw = static_cast<RawSample*>(sample);
  raw->data = r->bytes.data();
  raw->size = r->size;
  return true;
}

ddsi_serdata* SerdataToUntyped(const ddsi_serdata* d) {
  RawSerdata* u = NewSerdata(d->type, SDK_KEY);
  if (u != nullptr) u->type = nullptr;
  return u;
}

bool SerdataUntypedToSample(const ddsi_sertype*, const ddsi_serdata*, void*, void**, void*) {
  return true;
}

size_t SerdataPrint(const ddsi_sertype*, const ddsi_serdata* d, char* buf, size_t bufsize) {
  const int n =
      std::snprintf(buf, bufsize, "(%zu bytes of CDR)", static_cast<const RawSerdata*>(d)->size);
  return n < 0 ? 0 : static_cast<size_t>(n);
}

void SerdataGetKeyhash(const ddsi_serdata*, ddsi_keyhash* buf, bool) {
  std::memset(buf, 0, sizeof(*buf));
}

const ddsi_serdata_ops kSerdataOps = {
    .eqkey = SerdataEqKey,
    .get_size = SerdataSize,
    .from_ser = SerdataFromSer,
    .from_ser_iov = SerdataFromSerIov,
    .from_keyhash = SerdataFromKeyhash,
    .from_sample = SerdataFromSample,
    .to_ser = SerdataToSer,
    .to_ser_ref = SerdataToSerRef,
    .to_ser_unref = SerdataToSerUnref,
    .to_sample = SerdataToSample,
    .to_untyped = SerdataToUntyped,
    .untyped_to_sample = SerdataUntypedToSample,
    .free = SerdataFree,
    .print = SerdataPrint,
    .get_keyhash = SerdataGetKeyhash,
#ifdef DDS_HAS_SHM
    .get_sample_size = nullptr,
    .from_iox_buffer = nullptr,
#endif
};

// ---- sertype ops
// ---------------------------------------------------------------------------------
void SertypeFree(ddsi_sertype* tp) {
  ddsi_sertype_fini(tp);
  delete static_cast<RawSertype*>(tp);
}

void SertypeZeroSamples(const ddsi_sertype*, void* samples, size_t count) {
  std::memset(samples, 0, count * sizeof(RawSample));
}

void SertypeReallocSamples(void** ptrs, const ddsi_sertype*, void* old, size_t oldcount,
                           size_t count) {
  auto* fresh = static_cast<RawSample*>(std::realloc(old, count * sizeof(RawSample)));
  if (fresh != nullptr && count > oldcount) {
    std::memset(fresh + oldcount, 0, (count - oldcount) * sizeof(RawSample));
  }
  for (size_t i = 0; i < count; ++i) ptrs[i] = fresh + i;
}

void SertypeFreeSamples(const ddsi_sertype*, void** ptrs, size_t, dds_free_op_t op) {
  if ((op & DDS_FREE_ALL_BIT) != 0) std::free(ptrs[0]);
}

bool SertypeEqual(const ddsi_sertype* a, const ddsi_sertype* b) {
  return std::strcmp(a->type_name, b->type_name) == 0;
}

uint32_t SertypeHash(const ddsi_sertype* tp) {
  return static_cast<uint32_t>(std::hash<std::string_view>{}(tp->type_name));
}

size_t SertypeSerializedSize(const ddsi_sertype*, const void* sample) {
  return static_cast<const RawSample*>(sample)->size;
}

bool SertypeSerializeInto(const ddsi_sertype*, const void* sample, void* dst, size_t dst_size) {
  const auto* raw = static_cast<const RawSample*>(sample);
  if (raw->size > dst_size) return false;
  std::memcpy(dst, raw->data, raw->size);
  return true;
}

const ddsi_sertype_ops kSertypeOps = {
    .version = ddsi_sertype_v0,
    .arg = nullptr,
    .free = SertypeFree,
    .zero_samples = SertypeZeroSamples,
    .realloc_samples = SertypeReallocSamples,
    .free_samples = SertypeFreeSamples,
    .equal = SertypeEqual,
    .hash = SertypeHash,
    .type_id = nullptr,
    .type_map = nullptr,
    .type_info = nullptr,
    .derive_sertype = nullptr,
    .get_serialized_size = SertypeSerializedSize,
    .serialize_into = SertypeSerializeInto,
};

}  // namespace

ddsi_sertype* NewRawSertype(const std::string& dds_type_name) {
  auto* st = new RawSertype();
  ddsi_sertype_init(st, dds_type_name.c_str(), &kSertypeOps, &kSerdataOps,
                    /*topickind_no_key=*/true);
  st->allowed_data_representation = DDS_DATA_REPRESENTATION_FLAG_XCDR1;
  return st;
}

void FreeRawSertype(ddsi_sertype* sertype) { ddsi_sertype_unref(sertype); }

ddsi_serdata* NewRawSerdata(const ddsi_sertype* sertype, std::span<const uint8_t> bytes) {
  RawSample sample{bytes.data(), bytes.size()};
  return SerdataFromSample(sertype, SDK_DATA, &sample);
}

std::span<const uint8_t> RawSerdataBytes(const ddsi_serdata* serdata) {
  const auto* r = static_cast<const RawSerdata*>(serdata);
  return {r->bytes.data(), r->size};
}

}  // namespace avp::ros::dds::internal
