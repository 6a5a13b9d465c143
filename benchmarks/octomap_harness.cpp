#include "octomap_harness.h"

#include <chrono>
#include <cstdio>
#include <functional>
#include <string>

#include <dlfcn.h>

// AVP_OCTOMAP_FROM_HEADERS = 0 (libavp_octomap_harness.so): declare the OcTree templates
// `extern` before anything instantiates their members, so the calls below bind to the out-of-line
// definitions exported by liboctomap.so (Debian's -O2 build without NDEBUG) instead of copies
// compiled here. Only in-class (inline) members such as coordToKey and isNodeOccupied are still
// compiled here.
// AVP_OCTOMAP_FROM_HEADERS = 1 (libavp_octomap_harness_headers.so): instantiate everything here,
// with the project's flags; hidden visibility keeps these copies private to this library.
#include <octomap/OcTreeNode.h>
#include <octomap/OccupancyOcTreeBase.h>

#if !AVP_OCTOMAP_FROM_HEADERS
extern template class octomap::OcTreeBaseImpl<octomap::OcTreeNode,
                                              octomap::AbstractOccupancyOcTree>;
extern template class octomap::OccupancyOcTreeBase<octomap::OcTreeNode>;
#endif

#include <octomap/OcTree.h>

#if !AVP_OCTOMAP_FROM_HEADERS
// Members that liboctomap.so does not export (inlined everywhere there): the leaf iterator's
// helpers. They are compiled here; none of them is timed.
template bool
octomap::OcTreeBaseImpl<octomap::OcTreeNode, octomap::AbstractOccupancyOcTree>::nodeHasChildren(
    const octomap::OcTreeNode*) const;
template bool
octomap::OcTreeBaseImpl<octomap::OcTreeNode, octomap::AbstractOccupancyOcTree>::nodeChildExists(
    const octomap::OcTreeNode*, unsigned int) const;
template octomap::OcTreeNode*
octomap::OcTreeBaseImpl<octomap::OcTreeNode, octomap::AbstractOccupancyOcTree>::getNodeChild(
    octomap::OcTreeNode*, unsigned int) const;
#endif

#ifndef AVP_OCTOMAP_VERSION
#define AVP_OCTOMAP_VERSION "unknown"
#endif

namespace avp::bench {
namespace {

bool ToOctoKey(const VoxelKey& k, octomap::OcTreeKey& key) {
  const int32_t x = k.x + kOctoKeyOffset, y = k.y + kOctoKeyOffset, z = k.z + kOctoKeyOffset;
  if (x < 0 || y < 0 || z < 0 || x > 0xFFFF || y > 0xFFFF || z > 0xFFFF) return false;
  key = octomap::OcTreeKey(static_cast<octomap::key_type>(x), static_cast<octomap::key_type>(y),
                           static_cast<octomap::key_type>(z));
  return true;
}

VoxelKey FromOctoKey(const octomap::OcTreeKey& key) {
  return {static_cast<int32_t>(key[0]) - kOctoKeyOffset,
          static_cast<int32_t>(key[1]) - kOctoKeyOffset,
          static_cast<int32_t>(key[2]) - kOctoKeyOffset};
}

class Harness final : public OctoMapHarness {
 public:
  explicit Harness(double resolution_m) : tree_(resolution_m) {
    tree_.setProbHit(0.7);
    tree_.setProbMiss(0.4);
    tree_.setClampingThresMin(0.12);
    tree_.setClampingThresMax(0.97);
    tree_.setOccupancyThres(0.5);
  }

  size_t AddCloud(std::span<const Eigen::Vector3f> points_W) override {
    octomap::Pointcloud cloud;
    cloud.reserve(points_W.size());
    for (const Eigen::Vector3f& p : points_W) cloud.push_back(p.x(), p.y(), p.z());
    clouds_.push_back(std::move(cloud));
    return clouds_.size() - 1;
  }

  double Insert(size_t cloud, const Eigen::Vector3f& origin_W, double max_range_m,
                bool discretize) override {
    const octomap::point3d origin(origin_W.x(), origin_W.y(), origin_W.z());
    const auto start = std::chrono::steady_clock::now();
    tree_.insertPointCloud(clouds_.at(cloud), origin, max_range_m, /*lazy_eval=*/false, discretize);
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }

  void ReleaseClouds() override {
    clouds_.clear();
    clouds_.shrink_to_fit();
  }

  OctoState State(const VoxelKey& k) const override {
    octomap::OcTreeKey key;
    if (!ToOctoKey(k, key)) return OctoState::kUnknown;
    const octomap::OcTreeNode* node = tree_.search(key);
    if (node == nullptr) return OctoState::kUnknown;
    return tree_.isNodeOccupied(node) ? OctoState::kOccupied : OctoState::kFree;
  }

  void ForEachLeaf(const std::function<void(const VoxelKey&, int, bool)>& fn) const override {
    const unsigned max_depth = tree_.getTreeDepth();
    for (auto it = tree_.begin_leafs(), end = tree_.end_leafs(); it != end; ++it) {
      const int edge = 1 << (max_depth - it.getDepth());
      fn(FromOctoKey(it.getIndexKey()), edge, tree_.isNodeOccupied(*it));
    }
  }

  OctoRayCounts CastRay(const Eigen::Vector3f& from, const Eigen::Vector3f& to) const override {
    thread_local octomap::KeyRay ray;
    OctoRayCounts counts;
    if (!tree_.computeRayKeys(octomap::point3d(from.x(), from.y(), from.z()),
                              octomap::point3d(to.x(), to.y(), to.z()), ray)) {
      return counts;
    }
    for (const octomap::OcTreeKey& key : ray) {
      ++counts.visited;
      const octomap::OcTreeNode* node = tree_.search(key);
      if (node == nullptr) {
        ++counts.unknown;
      } else if (tree_.isNodeOccupied(node)) {
        counts.hit = true;
        break;
      } else {
        ++counts.free;
      }
    }
    return counts;
  }

  VoxelKey KeyOf(const Eigen::Vector3f& p) const override {
    return FromOctoKey(tree_.coordToKey(octomap::point3d(p.x(), p.y(), p.z())));
  }

  size_t MemoryUsage() const override { return tree_.memoryUsage(); }
  size_t NumLeaves() const override {
    size_t leaves = 0;
    for (auto it = tree_.begin_leafs(), end = tree_.end_leafs(); it != end; ++it) ++leaves;
    return leaves;
  }
  size_t NumNodes() const override { return tree_.size(); }

 private:
  octomap::OcTree tree_;
  std::vector<octomap::Pointcloud> clouds_;
};

}  // namespace

#if AVP_OCTOMAP_FROM_HEADERS

std::unique_ptr<OctoMapHarness> MakeOctoMapHarnessFromHeaders(double resolution_m) {
  return std::make_unique<Harness>(resolution_m);
}

#else

std::unique_ptr<OctoMapHarness> MakeOctoMapHarness(double resolution_m) {
  return std::make_unique<Harness>(resolution_m);
}

namespace {

/// The file of the shared object (or executable) that defines `symbol` for the dynamic linker.
std::string DefiningObject(const char* symbol) {
  void* address = dlsym(RTLD_DEFAULT, symbol);
  if (address == nullptr) return "not exported";
  Dl_info info{};
  if (dladdr(address, &info) == 0 || info.dli_fname == nullptr) return "?";
  std::string file = info.dli_fname;
  const size_t slash = file.rfind('/');
  return slash == std::string::npos ? file : file.substr(slash + 1);
}

}  // namespace

namespace {

// Itanium-mangled names of the OcTree members the benchmark times.
constexpr const char* kTimedSymbols[][2] = {
    {"insertPointCloud",
     "_ZN7octomap19OccupancyOcTreeBaseINS_10OcTreeNodeEE16insertPointCloudERKNS_10PointcloudERKN8"
     "octomath7Vector3Edbb"},
    {"computeUpdate",
     "_ZN7octomap19OccupancyOcTreeBaseINS_10OcTreeNodeEE13computeUpdateERKNS_10PointcloudERKN8"
     "octomath7Vector3ERNSt3tr113unordered_setINS_9OcTreeKeyENSC_7KeyHashESt8equal_toISC_"
     "ESaISC_EEESI_d"},
    {"updateNode",
     "_ZN7octomap19OccupancyOcTreeBaseINS_10OcTreeNodeEE10updateNodeERKNS_9OcTreeKeyEbb"},
    {"computeRayKeys",
     "_ZNK7octomap14OcTreeBaseImplINS_10OcTreeNodeENS_23AbstractOccupancyOcTreeEE14"
     "computeRayKeysERKN8octomath7Vector3ES7_RNS_6KeyRayE"},
    {"search",
     "_ZNK7octomap14OcTreeBaseImplINS_10OcTreeNodeENS_23AbstractOccupancyOcTreeEE6searchERKNS_"
     "9OcTreeKeyEj"},
};

}  // namespace

std::string OctoMapBuildInfo() {
  std::string first;
  std::string others;
  for (const auto& [name, symbol] : kTimedSymbols) {
    const std::string object = DefiningObject(symbol);
    if (first.empty()) first = object;
    if (object != first) others += std::string(", ") + name + " from " + object;
  }
  return std::string(AVP_OCTOMAP_VERSION) + ", OcTree code from " + first + others;
}

bool OctoMapCodeFromLibrary() {
  for (const auto& [name, symbol] : kTimedSymbols) {
    if (DefiningObject(symbol).rfind("liboctomap.so", 0) != 0) return false;
  }
  return true;
}

#endif  // AVP_OCTOMAP_FROM_HEADERS

}  // namespace avp::bench
