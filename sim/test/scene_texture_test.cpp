// Textures: Texture sampling, the colour fields of TriangleMesh (Append, Validate,
// ConnectedComponents), the renderer's per-hit colours, and textured OBJ / COLLADA / glTF scene
// files (docs/scene-format.md, "Textures").

#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/core/error.h>
#include <avp/core/limits.h>
#include <avp/io/image_codec.h>
#include <avp/io/png.h>
#include <avp/sim/mesh_builder.h>
#include <avp/sim/rgbd_renderer.h>
#include <avp/sim/scene_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::sim {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

/// sRGB 8-bit -> linear, the reference formula in double.
double Linear(int srgb) {
  const double s = srgb / 255.0;
  return s <= 0.04045 ? s / 12.92 : std::pow((s + 0.055) / 1.055, 2.4);
}

/// 2 x 2 texels: top row red (255, 0, 0), green (0, 255, 0); bottom row blue (0, 0, 255),
/// grey (128, 128, 128).
std::shared_ptr<Texture> TwoByTwo() {
  auto t = std::make_shared<Texture>();
  t->image = ImageRgb8(2, 2);
  const std::array<std::array<uint8_t, 3>, 4> texels = {
      {{255, 0, 0}, {0, 255, 0}, {0, 0, 255}, {128, 128, 128}}};
  for (int i = 0; i < 4; ++i) {
    for (int c = 0; c < 3; ++c) t->image(i % 2, i / 2, c) = texels[i][c];
  }
  t->source = "two-by-two";
  return t;
}

/// 16 x 16 pixels in quadrants as the image is seen: top-left red, top-right green, bottom-left
/// blue, bottom-right yellow.
ImageRgb8 QuadrantImage() {
  ImageRgb8 image(16, 16);
  for (int v = 0; v < 16; ++v) {
    for (int u = 0; u < 16; ++u) {
      const bool right = u >= 8;
      const bool bottom = v >= 8;
      const std::array<uint8_t, 3> c =
          !bottom
              ? (right ? std::array<uint8_t, 3>{0, 255, 0} : std::array<uint8_t, 3>{255, 0, 0})
              : (right ? std::array<uint8_t, 3>{255, 255, 0} : std::array<uint8_t, 3>{0, 0, 255});
      for (int k = 0; k < 3; ++k) image(u, v, k) = c[static_cast<size_t>(k)];
    }
  }
  return image;
}

// The test quad: x = 0.5, y in [-0.1, 0.1], z in [0.4, 0.6], seen from (0, 0, 0.5) looking
// along +x with image up = +z, so image right is world -y. Vertices in the order bottom-left,
// bottom-right, top-right, top-left as the camera sees them; texture coordinates in the OpenGL
// convention (t up) put the image upright.
const std::array<Eigen::Vector3f, 4> kQuadVertices = {
    Eigen::Vector3f(0.5f, 0.1f, 0.4f), Eigen::Vector3f(0.5f, -0.1f, 0.4f),
    Eigen::Vector3f(0.5f, -0.1f, 0.6f), Eigen::Vector3f(0.5f, 0.1f, 0.6f)};
const std::array<Eigen::Vector2f, 4> kQuadUvs = {Eigen::Vector2f(0, 0), Eigen::Vector2f(1, 0),
                                                 Eigen::Vector2f(1, 1), Eigen::Vector2f(0, 1)};

TriangleMesh QuadMesh() {
  TriangleMesh m;
  m.vertices.assign(kQuadVertices.begin(), kQuadVertices.end());
  m.triangles = {Eigen::Vector3i(0, 1, 2), Eigen::Vector3i(0, 2, 3)};
  return m;
}

CameraIntrinsics Camera() { return CameraIntrinsics::FromHorizontalFov(160, 120, 60.0, 0.1, 3.0); }
RigidTransform CameraPose() {
  return RigidTransform::LookAt({0.0, 0.0, 0.5}, {1.0, 0.0, 0.5}, Eigen::Vector3d::UnitZ());
}

/// 'R', 'G', 'B', 'Y' for a clearly red, green, blue or yellow sRGB pixel, '?' otherwise.
char ColorName(const ImageRgb8& rgb, int u, int v) {
  const int r = rgb(u, v, 0), g = rgb(u, v, 1), b = rgb(u, v, 2);
  const auto hi = [](int c) { return c > 150; };
  const auto lo = [](int c) { return c < 40; };
  if (hi(r) && lo(g) && lo(b)) return 'R';
  if (lo(r) && hi(g) && lo(b)) return 'G';
  if (lo(r) && lo(g) && hi(b)) return 'B';
  if (hi(r) && hi(g) && lo(b)) return 'Y';
  return '?';
}

/// The quadrants of the rendered quad, as "TL TR BL BR" colour names, each the name every pixel
/// of a 5 x 5 block at the quadrant's centre shares ('?' when they differ).
std::string RenderedQuadrants(const Scene& scene) {
  const RgbdRenderer renderer(scene);
  const RenderedFrame f = renderer.Render(Camera(), CameraPose());
  // The quad spans u, v in about [52, 107] x [32, 87]; quadrant centres at 66 / 93, 46 / 73.
  std::string out;
  for (const auto& [cu, cv] :
       std::array<std::pair<int, int>, 4>{{{66, 46}, {93, 46}, {66, 73}, {93, 73}}}) {
    char name = ColorName(f.rgbd.rgb, cu, cv);
    for (int dv = -2; dv <= 2; ++dv) {
      for (int du = -2; du <= 2; ++du) {
        if (ColorName(f.rgbd.rgb, cu + du, cv + dv) != name) name = '?';
      }
    }
    if (!out.empty()) out += ' ';
    out += name;
  }
  return out;
}

// ---- Texture ---------------------------------------------------------------------------------

TEST(TextureTest, SamplesBilinearInLinearRgbWithRepeatAndTUp) {
  const auto t = TwoByTwo();
  ASSERT_TRUE(t->Validate().ok());
  // Texel centres: (0.25, 0.75) is the top-left texel (t up), (0.75, 0.25) the bottom-right.
  EXPECT_TRUE(t->Sample({0.25f, 0.75f}).isApprox(Eigen::Vector3f(1, 0, 0)));
  EXPECT_TRUE(t->Sample({0.75f, 0.75f}).isApprox(Eigen::Vector3f(0, 1, 0)));
  EXPECT_TRUE(t->Sample({0.25f, 0.25f}).isApprox(Eigen::Vector3f(0, 0, 1)));
  const float grey = static_cast<float>(Linear(128));  // 0.2158605
  EXPECT_NEAR(grey, 0.2158605f, 1e-6f);
  EXPECT_TRUE(t->Sample({0.75f, 0.25f}).isApprox(Eigen::Vector3f::Constant(grey)));
  // Half way between red and green, in linear RGB (not sRGB).
  EXPECT_TRUE(t->Sample({0.5f, 0.75f}).isApprox(Eigen::Vector3f(0.5f, 0.5f, 0.0f)));
  // Repeat: whole numbers added change nothing; s = 0 is half way between the last column and
  // the first.
  EXPECT_TRUE(t->Sample({1.25f, -0.25f}).isApprox(t->Sample({0.25f, 0.75f})));
  EXPECT_TRUE(t->Sample({-3.25f, 2.25f}).isApprox(Eigen::Vector3f::Constant(grey)));
  EXPECT_TRUE(t->Sample({0.0f, 0.75f}).isApprox(Eigen::Vector3f(0.5f, 0.5f, 0.0f)));
  // Centre: the mean of the four texels.
  const Eigen::Vector3f mean((1.0f + grey) / 4, (1.0f + grey) / 4, (1.0f + grey) / 4);
  EXPECT_TRUE(t->Sample({0.5f, 0.5f}).isApprox(mean));
  EXPECT_TRUE(t->MeanColor().isApprox(mean));
  // Not finite: the mean colour.
  EXPECT_TRUE(t->Sample({std::nanf(""), 0.5f}).isApprox(mean));
  // The factor multiplies.
  auto f = TwoByTwo();
  f->factor = Eigen::Vector3f(0.5f, 1.0f, 0.25f);
  EXPECT_TRUE(f->Sample({0.75f, 0.25f}).isApprox(Eigen::Vector3f(0.5f, 1.0f, 0.25f) * grey));
  // A small triangle at the top-left texel's centre: red, 1 % of green blended in at its far
  // corner (the mean of 45 lattice samples).
  const Eigen::Vector3f small = t->MeanOverTriangle({0.25f, 0.75f}, {0.26f, 0.75f}, {0.25f, 0.76f});
  EXPECT_NEAR(small.x(), 1.0f, 0.02f);
  EXPECT_NEAR(small.y(), 0.0f, 0.02f);
  EXPECT_NEAR(small.z(), 0.0f, 0.02f);
  // A triangle over two repeats of the image: the four texels' colours, about equally (45
  // samples).
  const Eigen::Vector3f whole = t->MeanOverTriangle({0, 0}, {2, 0}, {0, 2});
  EXPECT_LT((whole - mean).cwiseAbs().maxCoeff(), 0.06f) << whole.transpose();
}

TEST(TextureTest, ValidateNamesTheProblem) {
  Texture empty;
  empty.source = "nothing.png";
  EXPECT_THAT(empty.Validate().message(), HasSubstr("'nothing.png' has no texels (0 x 0)"));
  EXPECT_EQ(empty.Sample({0.5f, 0.5f}), Eigen::Vector3f::Zero());  // black, never out of bounds
  auto t = TwoByTwo();
  t->factor = Eigen::Vector3f(1.5f, 1.0f, 1.0f);
  EXPECT_THAT(t->Validate().message(), HasSubstr("factor (1.5, 1, 1) must be in [0, 1]"));
}

// ---- TriangleMesh colours --------------------------------------------------------------------

TEST(TexturedMeshTest, AppendKeepsASharedTextureAndBakesMixes) {
  const std::shared_ptr<const Texture> tex = TwoByTwo();
  TriangleMesh a = QuadMesh();
  a.uvs.assign(kQuadUvs.begin(), kQuadUvs.end());
  a.texture = tex;
  ASSERT_TRUE(a.Validate().ok()) << a.Validate().ToString();

  // Into an empty mesh: the texture comes along.
  TriangleMesh empty;
  empty.Append(a);
  EXPECT_EQ(empty.texture, tex);
  EXPECT_EQ(empty.uvs.size(), 4u);
  EXPECT_TRUE(empty.Validate().ok());

  // Same texture: texture coordinates concatenated, still textured, vertices moved, uvs not.
  TriangleMesh same = a;
  same.Append(a, RigidTransform(Eigen::Vector3d(0, 0, 1)));
  EXPECT_EQ(same.texture, tex);
  ASSERT_EQ(same.uvs.size(), 8u);
  EXPECT_EQ(same.uvs[5], kQuadUvs[1]);
  EXPECT_TRUE(same.vertices[5].isApprox(kQuadVertices[1] + Eigen::Vector3f(0, 0, 1)));
  EXPECT_TRUE(same.face_albedo.empty());
  EXPECT_TRUE(same.Validate().ok());

  // A textured mesh and an untextured one: per-triangle colours, the texture baked (its mean
  // over each triangle), the plain part in its object's albedo.
  const Eigen::Vector3f plain_albedo(0.1f, 0.2f, 0.3f);
  TriangleMesh mixed = a;
  mixed.Append(QuadMesh(), RigidTransform::Identity(), Eigen::Vector3f(0.5f, 0.5f, 0.5f),
               plain_albedo);
  EXPECT_EQ(mixed.texture, nullptr);
  EXPECT_TRUE(mixed.uvs.empty());
  ASSERT_EQ(mixed.face_albedo.size(), 4u);
  EXPECT_TRUE(
      mixed.face_albedo[0].isApprox(tex->MeanOverTriangle(kQuadUvs[0], kQuadUvs[1], kQuadUvs[2])));
  EXPECT_EQ(mixed.face_albedo[2], plain_albedo);
  EXPECT_EQ(mixed.face_albedo[3], plain_albedo);
  EXPECT_TRUE(mixed.Validate().ok()) << mixed.Validate().ToString();
  EXPECT_EQ(mixed.FaceColors(Eigen::Vector3f::Zero()), mixed.face_albedo);

  // Without the albedos the mix cannot be coloured: an error, not a silent guess.
  TriangleMesh no_albedo = a;
  EXPECT_THROW(no_albedo.Append(QuadMesh()), Error);

  // Two different textures: both baked.
  TriangleMesh other = a;
  other.texture = TwoByTwo();
  TriangleMesh two = a;
  two.Append(other, RigidTransform::Identity(), Eigen::Vector3f::Zero(), Eigen::Vector3f::Zero());
  EXPECT_EQ(two.texture, nullptr);
  EXPECT_EQ(two.face_albedo.size(), 4u);

  // Plain meshes: the same albedo stays plain, different albedos become per-triangle colours;
  // the two-argument Append of plain meshes is unchanged.
  TriangleMesh p = QuadMesh();
  p.Append(QuadMesh(), RigidTransform::Identity(), plain_albedo, plain_albedo);
  EXPECT_FALSE(p.has_own_colors());
  p.Append(QuadMesh(), RigidTransform::Identity(), plain_albedo, Eigen::Vector3f(1, 0, 0));
  ASSERT_EQ(p.face_albedo.size(), 6u);
  EXPECT_EQ(p.face_albedo[3], plain_albedo);
  EXPECT_EQ(p.face_albedo[5], Eigen::Vector3f(1, 0, 0));
  TriangleMesh q = QuadMesh();
  q.Append(QuadMesh());
  EXPECT_FALSE(q.has_own_colors());
  EXPECT_EQ(q.triangles.size(), 4u);
  // Per-triangle colours and an appended per-triangle mesh concatenate.
  TriangleMesh r = p;
  r.Append(p);
  EXPECT_EQ(r.face_albedo.size(), 12u);
  EXPECT_TRUE(r.Validate().ok());
}

TEST(TexturedMeshTest, ValidateChecksSizesAndValues) {
  TriangleMesh m = QuadMesh();
  m.uvs = {Eigen::Vector2f(0, 0)};
  EXPECT_THAT(m.Validate().message(),
              HasSubstr("mesh has 1 texture coordinates for 4 vertices (one per vertex, or none)"));
  m.uvs.assign(kQuadUvs.begin(), kQuadUvs.end());
  m.uvs[2].x() = std::numeric_limits<float>::infinity();
  EXPECT_THAT(m.Validate().message(),
              HasSubstr("mesh texture coordinate 2 is not finite: (inf, 1)"));
  m.uvs.clear();
  m.texture = TwoByTwo();
  EXPECT_THAT(m.Validate().message(),
              HasSubstr("mesh has texture 'two-by-two' but no texture coordinates"));
  m.uvs.assign(kQuadUvs.begin(), kQuadUvs.end());
  EXPECT_TRUE(m.Validate().ok());
  m.face_albedo = {Eigen::Vector3f::Zero(), Eigen::Vector3f::Zero()};
  EXPECT_THAT(m.Validate().message(), HasSubstr("both texture 'two-by-two' and per-triangle"));
  m.texture.reset();
  EXPECT_TRUE(m.Validate().ok());
  m.face_albedo.pop_back();
  EXPECT_THAT(m.Validate().message(),
              HasSubstr("mesh has 1 per-triangle colours for 2 triangles (one per triangle, or "
                        "none)"));
  m.face_albedo = {Eigen::Vector3f::Zero(), Eigen::Vector3f(0.5f, 1.5f, 0.0f)};
  EXPECT_THAT(
      m.Validate().message(),
      HasSubstr("mesh colour of triangle 1 is (0.5, 1.5, 0); must be linear RGB in [0, 1]"));
}

TEST(TexturedMeshTest, ConnectedComponentsAndDescribeDifferenceCarryColours) {
  TriangleMesh two = QuadMesh();
  two.uvs.assign(kQuadUvs.begin(), kQuadUvs.end());
  two.texture = TwoByTwo();
  TriangleMesh moved = two;
  two.Append(moved, RigidTransform(Eigen::Vector3d(0, 1, 0)));
  const std::vector<TriangleMesh> parts = ConnectedComponents(two);
  ASSERT_EQ(parts.size(), 2u);
  for (const TriangleMesh& p : parts) {
    EXPECT_EQ(p.texture, two.texture);
    EXPECT_EQ(p.uvs.size(), p.vertices.size());
    EXPECT_TRUE(p.Validate().ok()) << p.Validate().ToString();
  }
  EXPECT_EQ(parts[1].uvs[2], kQuadUvs[2]);

  TriangleMesh faces = QuadMesh();
  faces.face_albedo = {Eigen::Vector3f(1, 0, 0), Eigen::Vector3f(0, 1, 0)};
  faces.Append(QuadMesh(), RigidTransform(Eigen::Vector3d(0, 1, 0)), Eigen::Vector3f::Zero(),
               Eigen::Vector3f(0, 0, 1));
  const std::vector<TriangleMesh> split = ConnectedComponents(faces);
  ASSERT_EQ(split.size(), 2u);
  EXPECT_EQ(split[0].face_albedo[1], Eigen::Vector3f(0, 1, 0));
  EXPECT_EQ(split[1].face_albedo[0], Eigen::Vector3f(0, 0, 1));

  Scene a;
  a.Add("quad", SemanticClass::kLeaf, Eigen::Vector3f::Constant(0.5f), parts[0]);
  Scene b = a;
  EXPECT_EQ(DescribeDifference(a, b), "");
  auto other = std::make_shared<Texture>(*parts[0].texture);
  other->image(0, 0, 1) = 7;
  std::get<TriangleMesh>(b.objects[0].shape).texture = other;
  EXPECT_THAT(DescribeDifference(a, b), HasSubstr("texture of 'quad' differs"));
  b = a;
  std::get<TriangleMesh>(b.objects[0].shape).uvs[0].x() = 0.5f;
  EXPECT_THAT(DescribeDifference(a, b), HasSubstr("texture coordinates"));
}

// ---- Renderer --------------------------------------------------------------------------------

Scene QuadScene(TriangleMesh mesh,
                const Eigen::Vector3f& albedo = Eigen::Vector3f(0.4f, 0.4f, 0.4f)) {
  Scene scene;
  scene.Add("quad", SemanticClass::kLeaf, albedo, std::move(mesh));
  return scene;
}

TEST(TexturedRenderTest, TextureAppearsUprightAtTheRightPixels) {
  TriangleMesh m = QuadMesh();
  m.uvs.assign(kQuadUvs.begin(), kQuadUvs.end());
  auto tex = std::make_shared<Texture>();
  tex->image = QuadrantImage();
  m.texture = tex;
  EXPECT_EQ(RenderedQuadrants(QuadScene(m)), "R G B Y");
  // Labels are the object's, as for any mesh.
  const Scene scene = QuadScene(m);
  const RenderedFrame f = RgbdRenderer(scene).Render(Camera(), CameraPose());
  EXPECT_EQ(f.instance_ids(80, 60), scene.objects[0].instance_id);
  EXPECT_EQ(f.class_ids(80, 60), static_cast<uint8_t>(SemanticClass::kLeaf));
  EXPECT_NEAR(f.rgbd.depth_m(80, 60), 0.5f, 1e-5f);
}

TEST(TexturedRenderTest, PerTriangleColoursAndUntouchedPlainMeshes) {
  // Two triangles, red (lower right, triangle 0) and blue (upper left, triangle 1).
  TriangleMesh m = QuadMesh();
  m.face_albedo = {Eigen::Vector3f(0.9f, 0.0f, 0.0f), Eigen::Vector3f(0.0f, 0.0f, 0.9f)};
  const RenderedFrame f = RgbdRenderer(QuadScene(m)).Render(Camera(), CameraPose());
  EXPECT_EQ(ColorName(f.rgbd.rgb, 100, 80), 'R');
  EXPECT_EQ(ColorName(f.rgbd.rgb, 60, 40), 'B');

  // Per-triangle colours equal to the albedo render exactly as the plain mesh (same tint).
  const Eigen::Vector3f albedo(0.3f, 0.6f, 0.2f);
  TriangleMesh same = QuadMesh();
  same.face_albedo = {albedo, albedo};
  const RenderedFrame plain =
      RgbdRenderer(QuadScene(QuadMesh(), albedo)).Render(Camera(), CameraPose());
  const RenderedFrame faces = RgbdRenderer(QuadScene(same, albedo)).Render(Camera(), CameraPose());
  EXPECT_TRUE(plain.rgbd.rgb == faces.rgbd.rgb);
}

// ---- Scene files -----------------------------------------------------------------------------

std::string Base64(const std::vector<uint8_t>& bytes) {
  static const char* kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (size_t i = 0; i < bytes.size(); i += 3) {
    const uint32_t n = (uint32_t{bytes[i]} << 16) |
                       (i + 1 < bytes.size() ? uint32_t{bytes[i + 1]} << 8 : 0u) |
                       (i + 2 < bytes.size() ? uint32_t{bytes[i + 2]} : 0u);
    out += kAlphabet[(n >> 18) & 63];
    out += kAlphabet[(n >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(n >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? kAlphabet[n & 63] : '=';
  }
  return out;
}

template <typename T>
void AppendBytes(std::vector<uint8_t>& out, const T& value) {
  const auto* p = reinterpret_cast<const uint8_t*>(&value);
  out.insert(out.end(), p, p + sizeof(T));
}

class TexturedSceneFileTest : public test::TempDirTest {
 protected:
  void WriteBytes(const std::string& name, const std::vector<uint8_t>& bytes) {
    std::ofstream(dir_ / name, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()),
               static_cast<std::streamsize>(bytes.size()));
  }
  void WriteQuadrantPng(const std::string& name) {
    ASSERT_TRUE(io::WritePngRgb8(dir_ / name, QuadrantImage()).ok());
  }
  /// quad.obj + quad.mtl: the quad with material quad_mat (Kd `kd`, map_Kd `map`).
  void WriteObj(const std::string& map, const std::string& kd = "0.5 0.5 0.5") {
    std::string obj = "mtllib quad.mtl\no quad\n";
    for (const Eigen::Vector3f& v : kQuadVertices) {
      obj += "v " + std::to_string(v.x()) + " " + std::to_string(v.y()) + " " +
             std::to_string(v.z()) + "\n";
    }
    for (const Eigen::Vector2f& t : kQuadUvs) {
      obj += "vt " + std::to_string(t.x()) + " " + std::to_string(t.y()) + "\n";
    }
    obj += "usemtl quad_mat\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n";
    Write("quad.obj", obj);
    Write("quad.mtl",
          "newmtl quad_mat\nKd " + kd + "\n" + (map.empty() ? "" : "map_Kd " + map + "\n"));
  }
  Result<Scene> Load(const std::string& mesh, const std::string& extra = "") {
    return LoadSceneFile(Write("scene.yaml", "version: 1\nmeshes:\n  - file: " + mesh +
                                                 "\n    up_axis: z\n    default_class: leaf\n" +
                                                 extra));
  }
  static std::string TextureWarnings(const Scene& s) {
    std::string out;
    for (const std::string& w : s.warnings) {
      if (w.find("texture") != std::string::npos) out += w + "\n";
    }
    return out;
  }
};

TEST_F(TexturedSceneFileTest, ObjMapKdIsRenderedUpright) {
  WriteQuadrantPng("quad.png");
  WriteObj("quad.png");
  const Result<Scene> r = Load("quad.obj");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->objects.size(), 1u);
  const TriangleMesh& m = std::get<TriangleMesh>(r->objects[0].shape);
  ASSERT_NE(m.texture, nullptr);
  EXPECT_EQ(m.uvs.size(), m.vertices.size());
  EXPECT_EQ(m.texture->factor, Eigen::Vector3f::Ones());  // OBJ: the texture replaces Kd
  EXPECT_EQ(m.texture->image, QuadrantImage());
  // Albedo: the texture's colour over the quad, about the mean of the four quadrants.
  EXPECT_LT((r->objects[0].albedo - Eigen::Vector3f(0.5f, 0.5f, 0.25f)).cwiseAbs().maxCoeff(),
            0.05f)
      << r->objects[0].albedo.transpose();
  EXPECT_EQ(TextureWarnings(*r), "");
  EXPECT_EQ(RenderedQuadrants(*r), "R G B Y");
}

TEST_F(TexturedSceneFileTest, ColladaImageIsRenderedUpright) {
  WriteQuadrantPng("quad.png");
  std::string positions, uvs;
  for (const Eigen::Vector3f& v : kQuadVertices) {
    positions +=
        std::to_string(v.x()) + " " + std::to_string(v.y()) + " " + std::to_string(v.z()) + " ";
  }
  for (const Eigen::Vector2f& t : kQuadUvs) {
    uvs += std::to_string(t.x()) + " " + std::to_string(t.y()) + " ";
  }
  Write("quad.dae", R"(<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="meter" meter="1"/><up_axis>Z_UP</up_axis></asset>
  <library_images>
    <image id="quad_png" name="quad_png"><init_from>quad.png</init_from></image>
  </library_images>
  <library_effects>
    <effect id="quad_fx">
      <profile_COMMON>
        <newparam sid="quad_surface"><surface type="2D"><init_from>quad_png</init_from></surface></newparam>
        <newparam sid="quad_sampler"><sampler2D><source>quad_surface</source></sampler2D></newparam>
        <technique sid="common">
          <lambert>
            <diffuse><texture texture="quad_sampler" texcoord="UVMap"/></diffuse>
          </lambert>
        </technique>
      </profile_COMMON>
    </effect>
  </library_effects>
  <library_materials>
    <material id="quad_mat" name="quad_mat"><instance_effect url="#quad_fx"/></material>
  </library_materials>
  <library_geometries>
    <geometry id="quad-mesh" name="quad">
      <mesh>
        <source id="quad-pos">
          <float_array id="quad-pos-array" count="12">)" +
                        positions + R"(</float_array>
          <technique_common><accessor source="#quad-pos-array" count="4" stride="3">
            <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
          </accessor></technique_common>
        </source>
        <source id="quad-uv">
          <float_array id="quad-uv-array" count="8">)" +
                        uvs + R"(</float_array>
          <technique_common><accessor source="#quad-uv-array" count="4" stride="2">
            <param name="S" type="float"/><param name="T" type="float"/>
          </accessor></technique_common>
        </source>
        <vertices id="quad-vtx"><input semantic="POSITION" source="#quad-pos"/></vertices>
        <triangles material="quad_sym" count="2">
          <input semantic="VERTEX" source="#quad-vtx" offset="0"/>
          <input semantic="TEXCOORD" source="#quad-uv" offset="1" set="0"/>
          <p>0 0 1 1 2 2 0 0 2 2 3 3</p>
        </triangles>
      </mesh>
    </geometry>
  </library_geometries>
  <library_visual_scenes>
    <visual_scene id="Scene" name="Scene">
      <node id="n1" name="quad_node">
        <instance_geometry url="#quad-mesh">
          <bind_material><technique_common>
            <instance_material symbol="quad_sym" target="#quad_mat">
              <bind_vertex_input semantic="UVMap" input_semantic="TEXCOORD" input_set="0"/>
            </instance_material>
          </technique_common></bind_material>
        </instance_geometry>
      </node>
    </visual_scene>
  </library_visual_scenes>
  <scene><instance_visual_scene url="#Scene"/></scene>
</COLLADA>
)");
  const Result<Scene> r = Load("quad.dae");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->objects.size(), 1u);
  const TriangleMesh& m = std::get<TriangleMesh>(r->objects[0].shape);
  ASSERT_NE(m.texture, nullptr) << TextureWarnings(*r);
  EXPECT_EQ(m.texture->image, QuadrantImage());
  EXPECT_EQ(TextureWarnings(*r), "");
  EXPECT_EQ(RenderedQuadrants(*r), "R G B Y");
}

/// The quad's glTF buffer (92 bytes): positions, texture coordinates, indices. glTF's texture
/// coordinates have t down (origin at the image's top-left): (s, 1 - t) of the OpenGL ones.
std::vector<uint8_t> QuadGltfBuffer() {
  std::vector<uint8_t> buffer;
  for (const Eigen::Vector3f& v : kQuadVertices) {
    for (int k = 0; k < 3; ++k) AppendBytes(buffer, v[k]);
  }
  for (const Eigen::Vector2f& t : kQuadUvs) {
    AppendBytes(buffer, t.x());
    AppendBytes(buffer, 1.0f - t.y());
  }
  for (const uint16_t i : {0, 1, 2, 0, 2, 3}) AppendBytes(buffer, i);
  return buffer;
}

/// A glTF 2 file holding the quad, its buffer and `image_uri` as its base-colour texture, with
/// baseColorFactor `factor`.
std::string QuadGltf(const std::string& image_uri, const std::string& factor) {
  const std::vector<uint8_t> buffer = QuadGltfBuffer();
  return R"({"asset": {"version": "2.0"}, "scene": 0,
  "scenes": [{"nodes": [0]}],
  "nodes": [{"name": "quad_node", "mesh": 0}],
  "meshes": [{"name": "quad", "primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1},
              "indices": 2, "material": 0}]}],
  "materials": [{"name": "quad_mat", "pbrMetallicRoughness": {
                 "baseColorTexture": {"index": 0}, "baseColorFactor": )" +
         factor + R"(}}],
  "textures": [{"source": 0}],
  "images": [{"uri": ")" +
         image_uri + R"("}],
  "buffers": [{"byteLength": 92, "uri": "data:application/octet-stream;base64,)" +
         Base64(buffer) + R"("}],
  "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                  {"buffer": 0, "byteOffset": 48, "byteLength": 32},
                  {"buffer": 0, "byteOffset": 80, "byteLength": 12}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                 "min": [0.5, -0.1, 0.4], "max": [0.5, 0.1, 0.6]},
                {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}]})";
}

TEST_F(TexturedSceneFileTest, GltfEmbeddedPngTimesBaseColorFactorIsRenderedUpright) {
  const Result<std::vector<uint8_t>> png = io::EncodePng(QuadrantImage());
  ASSERT_TRUE(png.ok());
  Write("quad.gltf", QuadGltf("data:image/png;base64," + Base64(*png), "[1.0, 0.5, 1.0, 1.0]"));
  const Result<Scene> r = Load("quad.gltf");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->objects.size(), 1u);
  const TriangleMesh& m = std::get<TriangleMesh>(r->objects[0].shape);
  ASSERT_NE(m.texture, nullptr) << TextureWarnings(*r);
  EXPECT_EQ(m.texture->image, QuadrantImage());
  EXPECT_THAT(m.texture->source, HasSubstr("embedded texture 0"));
  EXPECT_TRUE(m.texture->factor.isApprox(Eigen::Vector3f(1.0f, 0.5f, 1.0f)));
  EXPECT_LT((r->objects[0].albedo - Eigen::Vector3f(0.5f, 0.25f, 0.25f)).cwiseAbs().maxCoeff(),
            0.05f)
      << r->objects[0].albedo.transpose();
  EXPECT_EQ(TextureWarnings(*r), "");
  EXPECT_EQ(RenderedQuadrants(*r), "R G B Y");
}

TEST_F(TexturedSceneFileTest, GlbWithThePngInItsBinaryChunkIsRenderedUpright) {
  const Result<std::vector<uint8_t>> png = io::EncodePng(QuadrantImage());
  ASSERT_TRUE(png.ok());
  std::vector<uint8_t> bin = QuadGltfBuffer();  // 92 bytes, then the PNG
  bin.insert(bin.end(), png->begin(), png->end());
  while (bin.size() % 4 != 0) bin.push_back(0);
  std::string json = R"({"asset": {"version": "2.0"}, "scene": 0,
  "scenes": [{"nodes": [0]}],
  "nodes": [{"name": "quad_node", "mesh": 0}],
  "meshes": [{"name": "quad", "primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1},
              "indices": 2, "material": 0}]}],
  "materials": [{"name": "quad_mat", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
  "textures": [{"source": 0}],
  "images": [{"bufferView": 3, "mimeType": "image/png"}],
  "buffers": [{"byteLength": )" +
                     std::to_string(bin.size()) + R"(}],
  "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                  {"buffer": 0, "byteOffset": 48, "byteLength": 32},
                  {"buffer": 0, "byteOffset": 80, "byteLength": 12},
                  {"buffer": 0, "byteOffset": 92, "byteLength": )" +
                     std::to_string(png->size()) + R"(}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                 "min": [0.5, -0.1, 0.4], "max": [0.5, 0.1, 0.6]},
                {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}]})";
  while (json.size() % 4 != 0) json += ' ';
  // GLB: a 12-byte header, a JSON chunk and a BIN chunk (little-endian lengths and tags).
  std::vector<uint8_t> glb;
  AppendBytes(glb, uint32_t{0x46546C67});  // "glTF"
  AppendBytes(glb, uint32_t{2});
  AppendBytes(glb, static_cast<uint32_t>(12 + 8 + json.size() + 8 + bin.size()));
  AppendBytes(glb, static_cast<uint32_t>(json.size()));
  AppendBytes(glb, uint32_t{0x4E4F534A});  // "JSON"
  glb.insert(glb.end(), json.begin(), json.end());
  AppendBytes(glb, static_cast<uint32_t>(bin.size()));
  AppendBytes(glb, uint32_t{0x004E4942});  // "BIN\0"
  glb.insert(glb.end(), bin.begin(), bin.end());
  WriteBytes("quad.glb", glb);
  const Result<Scene> r = Load("quad.glb");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->objects.size(), 1u);
  const TriangleMesh& m = std::get<TriangleMesh>(r->objects[0].shape);
  ASSERT_NE(m.texture, nullptr) << TextureWarnings(*r);
  EXPECT_EQ(m.texture->image, QuadrantImage());
  EXPECT_THAT(m.texture->source, HasSubstr("'quad.glb' embedded texture 0"));
  EXPECT_EQ(RenderedQuadrants(*r), "R G B Y");
}

TEST_F(TexturedSceneFileTest, GltfExternalImageUriIsResolvedNextToTheFile) {
  WriteQuadrantPng("quad image.png");
  Write("quad.gltf", QuadGltf("quad%20image.png", "[1.0, 1.0, 1.0, 1.0]"));
  const Result<Scene> r = Load("quad.gltf");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const TriangleMesh& m = std::get<TriangleMesh>(r->objects[0].shape);
  ASSERT_NE(m.texture, nullptr) << TextureWarnings(*r);
  EXPECT_EQ(RenderedQuadrants(*r), "R G B Y");
}

TEST_F(TexturedSceneFileTest, MissingTextureWarnsAndUsesTheMaterialColour) {
  WriteObj("textures/missing.png", "0.2 0.4 0.6");
  const Result<Scene> r = Load("quad.obj");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const TriangleMesh& m = std::get<TriangleMesh>(r->objects[0].shape);
  EXPECT_EQ(m.texture, nullptr);
  EXPECT_TRUE(m.uvs.empty());
  EXPECT_TRUE(r->objects[0].albedo.isApprox(Eigen::Vector3f(0.2f, 0.4f, 0.6f)));
  const std::string w = TextureWarnings(*r);
  EXPECT_THAT(w, HasSubstr("scene.yaml: meshes[0]: mesh 'quad.obj': texture '"));
  EXPECT_THAT(w, HasSubstr("textures/missing.png' is not rendered"));
  EXPECT_THAT(w, HasSubstr("does not exist"));
  EXPECT_THAT(w, HasSubstr("1 part ('quad/quad') uses the material colour"));
}

TEST_F(TexturedSceneFileTest, TexturesPastTheSceneBudgetWarnAndUseTheMaterialColour) {
  WriteQuadrantPng("quad.png");
  WriteObj("quad.png", "0.2 0.4 0.6");
  const uint64_t texels = static_cast<uint64_t>(QuadrantImage().width()) *
                          static_cast<uint64_t>(QuadrantImage().height());
  {
    const ScopedLimit budget(MaxSceneTexturePixels(), texels - 1);
    const Result<Scene> r = Load("quad.obj");
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    const TriangleMesh& m = std::get<TriangleMesh>(r->objects[0].shape);
    EXPECT_EQ(m.texture, nullptr);
    EXPECT_TRUE(r->objects[0].albedo.isApprox(Eigen::Vector3f(0.2f, 0.4f, 0.6f)));
    const std::string w = TextureWarnings(*r);
    EXPECT_THAT(w, HasSubstr("max_scene_texture_pixels"));
    EXPECT_THAT(w, HasSubstr("1 part ('quad/quad') uses the material colour"));
  }
  const ScopedLimit exact(MaxSceneTexturePixels(), texels);
  const Result<Scene> r = Load("quad.obj");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_NE(std::get<TriangleMesh>(r->objects[0].shape).texture, nullptr);
  EXPECT_EQ(TextureWarnings(*r), "");
}

TEST_F(TexturedSceneFileTest, CorruptOrOversizedImagesWarnWithoutCrashing) {
  // A PNG signature followed by garbage.
  WriteBytes("quad.png", {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n', 1, 2, 3, 4, 5, 6, 7});
  WriteObj("quad.png", "0.2 0.4 0.6");
  Result<Scene> r = Load("quad.obj");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(std::get<TriangleMesh>(r->objects[0].shape).texture, nullptr);
  EXPECT_TRUE(r->objects[0].albedo.isApprox(Eigen::Vector3f(0.2f, 0.4f, 0.6f)));
  EXPECT_THAT(TextureWarnings(*r), HasSubstr("quad.png' is not rendered: "));

  // A real PNG whose header declares 100000 x 100000 pixels: refused before decoding.
  Result<std::vector<uint8_t>> png = io::EncodePng(QuadrantImage());
  ASSERT_TRUE(png.ok());
  std::vector<uint8_t> big = *png;
  for (const size_t at : {size_t{16}, size_t{20}}) {  // IHDR width, height (big-endian)
    big[at] = 0;
    big[at + 1] = 0x01;
    big[at + 2] = 0x86;
    big[at + 3] = 0xa0;
  }
  WriteBytes("quad.png", big);
  r = Load("quad.obj");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(std::get<TriangleMesh>(r->objects[0].shape).texture, nullptr);
  EXPECT_THAT(TextureWarnings(*r), HasSubstr("max_image_pixels"));

  // An embedded image that is not one.
  Write("quad.gltf", QuadGltf("data:image/png;base64," + Base64({1, 2, 3, 4, 5, 6, 7, 8, 9}),
                              "[1.0, 1.0, 1.0, 1.0]"));
  r = Load("quad.gltf");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(std::get<TriangleMesh>(r->objects[0].shape).texture, nullptr);
  EXPECT_THAT(TextureWarnings(*r), HasSubstr("'quad.gltf' embedded texture 0"));
}

TEST_F(TexturedSceneFileTest, ExplicitColoursAndMaterialsIgnoreDropTheTexture) {
  WriteQuadrantPng("quad.png");
  WriteObj("quad.png");
  // An entry colour beats the texture.
  Result<Scene> r = Load("quad.obj", "    color: [0.1, 0.7, 0.1]\n");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(std::get<TriangleMesh>(r->objects[0].shape).texture, nullptr);
  EXPECT_TRUE(r->objects[0].albedo.isApprox(Eigen::Vector3f(0.1f, 0.7f, 0.1f)));
  // So does a rule's.
  r = Load("quad.obj", "    classes: [{match: quad, class: leaf, color: [0.7, 0.1, 0.1]}]\n");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(std::get<TriangleMesh>(r->objects[0].shape).texture, nullptr);
  EXPECT_TRUE(r->objects[0].albedo.isApprox(Eigen::Vector3f(0.7f, 0.1f, 0.1f)));
  // `materials: ignore` drops textures with the material colours: the class default.
  r = Load("quad.obj", "    materials: ignore\n");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(std::get<TriangleMesh>(r->objects[0].shape).texture, nullptr);
  EXPECT_TRUE(r->objects[0].albedo.isApprox(DefaultClassColor(SemanticClass::kLeaf)));
}

}  // namespace
}  // namespace avp::sim
