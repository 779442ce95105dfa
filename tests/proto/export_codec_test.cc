// The Export codec (proto/export_codec.h): a request with no options is core's defaults for its
// format, every field reads into the spec and is written back from it (the glTF format and the
// level of detail and the region included), a spec survives the round trip, and every refusal
// is INVALID_ARGUMENT naming its field at core's limits.
#include "proto/export_codec.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"

namespace plx {
namespace {

using ::testing::StartsWith;

constexpr uint64_t kTriangleLimit = static_cast<uint64_t>(kDefaultMaxMeshTriangles);

pb::ExportRequest MeshRequest() {
  pb::ExportRequest request;
  request.set_format(pb::EXPORT_FORMAT_MESH);
  return request;
}

// A mesh spec with every option away from its default.
ExportSpec ChosenMeshSpec() {
  ExportSpec spec;
  spec.mesh = true;
  spec.mesh_options.iso_level = 31.5f;
  spec.mesh_options.min_component_triangles = 40;
  spec.mesh_options.max_triangles = 123456;
  spec.mesh_options.keep_unobserved = true;
  spec.mesh_options.color_mode = MeshColorMode::kViewAlongNormal;
  spec.lod_triangles = 5000;
  spec.mesh_options.region = AxisBox{{-1.5, -0.25, 0.0}, {0.125, 2.5, 3.0}};
  spec.mesh_surface = MeshSurface::kDensity;
  return spec;
}

void ExpectSameSpec(const ExportSpec& got, const ExportSpec& want) {
  EXPECT_EQ(got.mesh, want.mesh);
  EXPECT_EQ(got.min_density, want.min_density);
  EXPECT_EQ(got.mesh_options.iso_level, want.mesh_options.iso_level);
  EXPECT_EQ(got.mesh_options.min_component_triangles, want.mesh_options.min_component_triangles);
  EXPECT_EQ(got.mesh_options.max_triangles, want.mesh_options.max_triangles);
  EXPECT_EQ(got.mesh_options.keep_unobserved, want.mesh_options.keep_unobserved);
  EXPECT_EQ(got.mesh_options.color_mode, want.mesh_options.color_mode);
  EXPECT_EQ(got.mesh_format, want.mesh_format);
  EXPECT_EQ(got.lod_triangles, want.lod_triangles);
  EXPECT_EQ(got.mesh_options.region, want.mesh_options.region);
  EXPECT_EQ(got.mesh_surface, want.mesh_surface);
}

TEST(ExportCodecTest, AnEmptyRequestIsPointsAtCoresDensity) {
  const absl::StatusOr<ExportSpec> spec = ExportSpecFromProto(pb::ExportRequest());
  ASSERT_TRUE(spec.ok()) << spec.status();
  EXPECT_FALSE(spec->mesh);
  EXPECT_EQ(spec->min_density, kDefaultExportMinDensity);
}

TEST(ExportCodecTest, AMeshRequestWithNoOptionsIsCoresMeshDefaults) {
  const absl::StatusOr<ExportSpec> spec = ExportSpecFromProto(MeshRequest());
  ASSERT_TRUE(spec.ok()) << spec.status();
  EXPECT_TRUE(spec->mesh);
  EXPECT_EQ(spec->mesh_options.iso_level, kDefaultMeshIsoLevel);
  EXPECT_EQ(spec->mesh_options.max_triangles, kDefaultMaxMeshTriangles);
  EXPECT_EQ(spec->mesh_options.min_component_triangles, 0);
  EXPECT_FALSE(spec->mesh_options.keep_unobserved);
  EXPECT_EQ(spec->mesh_options.color_mode, MeshColorMode::kDc);
  EXPECT_EQ(spec->mesh_format, MeshFileFormat::kPly);
  EXPECT_EQ(spec->lod_triangles, 0);  // the full mesh
}

TEST(ExportCodecTest, MeshGlbIsTheSameMeshAsBinaryGltf) {
  pb::ExportRequest request;
  request.set_format(pb::EXPORT_FORMAT_MESH_GLB);
  const absl::StatusOr<ExportSpec> spec = ExportSpecFromProto(request);
  ASSERT_TRUE(spec.ok()) << spec.status();
  EXPECT_TRUE(spec->mesh);
  EXPECT_EQ(spec->mesh_format, MeshFileFormat::kGlb);
  EXPECT_EQ(spec->mesh_options.iso_level, kDefaultMeshIsoLevel);
  EXPECT_EQ(spec->lod_triangles, 0);
  request.set_lod_triangles(777);
  request.set_min_density(1.0f);  // a points field on a mesh format
  const absl::StatusOr<ExportSpec> refused = ExportSpecFromProto(request);
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
  request.set_min_density(0.0f);
  const absl::StatusOr<ExportSpec> lod = ExportSpecFromProto(request);
  ASSERT_TRUE(lod.ok()) << lod.status();
  EXPECT_EQ(lod->lod_triangles, 777);
}

TEST(ExportCodecTest, EveryFieldIsRead) {
  pb::ExportRequest points;
  points.set_min_density(0.75f);
  const absl::StatusOr<ExportSpec> p = ExportSpecFromProto(points);
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_FALSE(p->mesh);
  EXPECT_EQ(p->min_density, 0.75f);

  pb::ExportRequest mesh = MeshRequest();
  mesh.set_iso_level(31.5f);
  mesh.set_min_component_triangles(40);
  mesh.set_max_triangles(123456);
  mesh.set_keep_unobserved(true);
  mesh.set_mesh_color(pb::MESH_COLOR_ALONG_NORMAL);
  mesh.set_lod_triangles(5000);
  pb::BoundingBox* region = mesh.mutable_region();
  region->set_min_x(-1.5);
  region->set_min_y(-0.25);
  region->set_min_z(0.0);
  region->set_max_x(0.125);
  region->set_max_y(2.5);
  region->set_max_z(3.0);
  mesh.set_mesh_surface(pb::MESH_SURFACE_DENSITY);
  const absl::StatusOr<ExportSpec> m = ExportSpecFromProto(mesh);
  ASSERT_TRUE(m.ok()) << m.status();
  ExpectSameSpec(*m, ChosenMeshSpec());

  mesh.set_mesh_surface(static_cast<pb::MeshSurface>(7));
  const absl::StatusOr<ExportSpec> unknown = ExportSpecFromProto(mesh);
  EXPECT_EQ(unknown.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(unknown.status().message().find("mesh_surface"), std::string::npos);
  points.set_mesh_surface(pb::MESH_SURFACE_OBSERVED);
  const absl::StatusOr<ExportSpec> on_points = ExportSpecFromProto(points);
  EXPECT_EQ(on_points.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(on_points.status().message().find("mesh_surface"), std::string::npos);
}

TEST(ExportCodecTest, EveryFieldIsWritten) {
  const pb::ExportRequest mesh = ExportSpecToProto(ChosenMeshSpec());
  EXPECT_EQ(mesh.format(), pb::EXPORT_FORMAT_MESH);
  EXPECT_EQ(mesh.iso_level(), 31.5f);
  EXPECT_EQ(mesh.min_component_triangles(), 40u);
  EXPECT_EQ(mesh.max_triangles(), 123456u);
  EXPECT_TRUE(mesh.keep_unobserved());
  EXPECT_EQ(mesh.mesh_color(), pb::MESH_COLOR_ALONG_NORMAL);
  EXPECT_EQ(mesh.lod_triangles(), 5000u);
  ASSERT_TRUE(mesh.has_region());
  EXPECT_EQ(mesh.region().min_x(), -1.5);
  EXPECT_EQ(mesh.region().min_y(), -0.25);
  EXPECT_EQ(mesh.region().min_z(), 0.0);
  EXPECT_EQ(mesh.region().max_x(), 0.125);
  EXPECT_EQ(mesh.region().max_y(), 2.5);
  EXPECT_EQ(mesh.region().max_z(), 3.0);
  EXPECT_EQ(mesh.min_density(), 0.0f);  // points only: the daemon refuses it on a mesh
  EXPECT_TRUE(mesh.map().empty());      // the caller's

  ExportSpec points_spec;
  points_spec.min_density = 0.75f;
  points_spec.mesh_options = ChosenMeshSpec().mesh_options;  // not the format's: not sent
  const pb::ExportRequest points = ExportSpecToProto(points_spec);
  EXPECT_EQ(points.format(), pb::EXPORT_FORMAT_POINTS);
  EXPECT_EQ(points.min_density(), 0.75f);
  EXPECT_EQ(points.iso_level(), 0.0f);
  EXPECT_EQ(points.min_component_triangles(), 0u);
  EXPECT_EQ(points.max_triangles(), 0u);
  EXPECT_FALSE(points.keep_unobserved());
  EXPECT_EQ(points.mesh_color(), pb::MESH_COLOR_DC);
  EXPECT_EQ(points.lod_triangles(), 0u);
  EXPECT_FALSE(points.has_region());

  ExportSpec glb_spec = ChosenMeshSpec();
  glb_spec.mesh_format = MeshFileFormat::kGlb;
  EXPECT_EQ(ExportSpecToProto(glb_spec).format(), pb::EXPORT_FORMAT_MESH_GLB);
}

TEST(ExportCodecTest, DefaultsAreSentResolved) {
  const pb::ExportRequest points = ExportSpecToProto(ExportSpec());
  EXPECT_EQ(points.min_density(), kDefaultExportMinDensity);
  ExportSpec mesh_spec;
  mesh_spec.mesh = true;
  const pb::ExportRequest mesh = ExportSpecToProto(mesh_spec);
  EXPECT_EQ(mesh.iso_level(), kDefaultMeshIsoLevel);
  EXPECT_EQ(mesh.max_triangles(), kTriangleLimit);
  EXPECT_EQ(mesh.min_component_triangles(), 0u);
  EXPECT_EQ(mesh.mesh_color(), pb::MESH_COLOR_DC);
}

TEST(ExportCodecTest, ASpecSurvivesTheRoundTrip) {
  std::vector<ExportSpec> specs(6);
  specs[1].min_density = 0.25f;
  specs[2].mesh = true;
  specs[3] = ChosenMeshSpec();
  specs[4] = ChosenMeshSpec();
  specs[4].mesh_options.color_mode = MeshColorMode::kDc;
  specs[4].mesh_options.keep_unobserved = false;
  specs[4].mesh_options.max_triangles = kDefaultMaxMeshTriangles;  // the limit itself
  specs[4].mesh_options.min_component_triangles = kDefaultMaxMeshTriangles;
  specs[4].lod_triangles = kMaxLodTriangles;
  specs[5] = ChosenMeshSpec();
  specs[5].mesh_format = MeshFileFormat::kGlb;
  for (size_t i = 0; i < specs.size(); ++i) {
    SCOPED_TRACE(i);
    const absl::StatusOr<ExportSpec> back = ExportSpecFromProto(ExportSpecToProto(specs[i]));
    ASSERT_TRUE(back.ok()) << back.status();
    ExpectSameSpec(*back, specs[i]);
  }
}

TEST(ExportCodecTest, AnExplicitRequestSurvivesTheRoundTrip) {
  pb::ExportRequest mesh = MeshRequest();
  mesh.set_iso_level(12.0f);
  mesh.set_min_component_triangles(3);
  mesh.set_max_triangles(99);
  mesh.set_keep_unobserved(true);
  mesh.set_mesh_color(pb::MESH_COLOR_ALONG_NORMAL);
  mesh.set_lod_triangles(10);
  pb::BoundingBox* region = mesh.mutable_region();
  region->set_min_x(-1.0);
  region->set_min_y(-2.0);
  region->set_min_z(0.1);
  region->set_max_x(1.0);
  region->set_max_y(2.0);
  region->set_max_z(2.9);
  pb::ExportRequest glb = mesh;
  glb.set_format(pb::EXPORT_FORMAT_MESH_GLB);
  pb::ExportRequest points;
  points.set_min_density(7.0f);
  for (const pb::ExportRequest& request : {mesh, glb, points}) {
    const absl::StatusOr<ExportSpec> spec = ExportSpecFromProto(request);
    ASSERT_TRUE(spec.ok()) << spec.status();
    EXPECT_EQ(ExportSpecToProto(*spec).SerializeAsString(), request.SerializeAsString())
        << request.ShortDebugString();
  }
}

TEST(ExportCodecTest, EveryRefusalNamesItsField) {
  constexpr float nan = std::numeric_limits<float>::quiet_NaN();
  constexpr float inf = std::numeric_limits<float>::infinity();
  struct Case {
    std::function<void(pb::ExportRequest*)> set;
    std::string message_start;
  };
  const std::string bad_density =
      absl::StrCat("min_density: must be finite and >= 0 (0 = the default, ",
                   kDefaultExportMinDensity, "), got ");
  const std::string bad_iso = absl::StrCat("iso_level: must be finite and >= 0 (0 = the default, ",
                                           kDefaultMeshIsoLevel, "), got ");
  const auto points = [](pb::ExportRequest* r) { r->set_format(pb::EXPORT_FORMAT_POINTS); };
  const std::vector<Case> cases = {
      {[](pb::ExportRequest* r) { r->set_format(static_cast<pb::ExportFormat>(7)); },
       "format: unknown value 7 (POINTS, MESH or MESH_GLB)"},
      {[&](pb::ExportRequest* r) {
         points(r);
         r->set_min_density(-1.0f);
       },
       bad_density + "-1"},
      {[&](pb::ExportRequest* r) {
         points(r);
         r->set_min_density(nan);
       },
       bad_density},
      {[&](pb::ExportRequest* r) {
         points(r);
         r->set_min_density(inf);
       },
       bad_density},
      {[](pb::ExportRequest* r) { r->set_min_density(-2.0f); }, bad_density + "-2"},
      {[](pb::ExportRequest* r) { r->set_iso_level(-1.0f); }, bad_iso + "-1"},
      {[](pb::ExportRequest* r) { r->set_iso_level(nan); }, bad_iso},
      {[](pb::ExportRequest* r) { r->set_iso_level(-inf); }, bad_iso},
      {[&](pb::ExportRequest* r) {
         points(r);
         r->set_iso_level(-1.0f);
       },
       bad_iso},
      // A field of the other format.
      {[](pb::ExportRequest* r) { r->set_min_density(5.0f); },
       "min_density: applies to format POINTS only (a mesh takes iso_level)"},
      {[&](pb::ExportRequest* r) {
         points(r);
         r->set_iso_level(50.0f);
       },
       "iso_level: applies to formats MESH and MESH_GLB only"},
      {[&](pb::ExportRequest* r) {
         points(r);
         r->set_min_component_triangles(1);
       },
       "min_component_triangles: applies to formats MESH and MESH_GLB only"},
      {[&](pb::ExportRequest* r) {
         points(r);
         r->set_max_triangles(1);
       },
       "max_triangles: applies to formats MESH and MESH_GLB only"},
      {[&](pb::ExportRequest* r) {
         points(r);
         r->set_keep_unobserved(true);
       },
       "keep_unobserved: applies to formats MESH and MESH_GLB only"},
      {[&](pb::ExportRequest* r) {
         points(r);
         r->set_mesh_color(pb::MESH_COLOR_ALONG_NORMAL);
       },
       "mesh_color: applies to formats MESH and MESH_GLB only"},
      {[&](pb::ExportRequest* r) {
         points(r);
         r->set_lod_triangles(100);
       },
       "lod_triangles: applies to formats MESH and MESH_GLB only"},
      {[&](pb::ExportRequest* r) {
         points(r);
         r->mutable_region()->set_max_x(1.0);
       },
       "region: applies to formats MESH and MESH_GLB only"},
      // Mesh options out of range.
      {[](pb::ExportRequest* r) { r->set_mesh_color(static_cast<pb::MeshColor>(9)); },
       "mesh_color: unknown value 9"},
      {[](pb::ExportRequest* r) { r->set_max_triangles(kTriangleLimit + 1); },
       absl::StrCat("max_triangles: at most ", kDefaultMaxMeshTriangles, " (0 = that), got ",
                    kTriangleLimit + 1)},
      {[](pb::ExportRequest* r) { r->set_lod_triangles(kTriangleLimit + 1); },
       absl::StrCat("lod_triangles: at most ", kMaxLodTriangles, " (0 = the full mesh), got ",
                    kTriangleLimit + 1)},
      {[](pb::ExportRequest* r) {
         r->set_format(pb::EXPORT_FORMAT_MESH_GLB);
         r->set_lod_triangles(uint64_t{1} << 40);
       },
       "lod_triangles: at most "},
      {[](pb::ExportRequest* r) { r->set_min_component_triangles(uint64_t{1} << 40); },
       absl::StrCat("min_component_triangles: at most ", kDefaultMaxMeshTriangles, ", got ",
                    uint64_t{1} << 40)},
  };
  for (const Case& c : cases) {
    pb::ExportRequest request = MeshRequest();
    c.set(&request);
    SCOPED_TRACE(request.ShortDebugString());
    const absl::StatusOr<ExportSpec> spec = ExportSpecFromProto(request);
    ASSERT_FALSE(spec.ok());
    EXPECT_EQ(spec.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(std::string(spec.status().message()), StartsWith(c.message_start));
  }
}

// A box a mesh request names: set, it reaches core as MeshOptions::region; refused unless every
// coordinate is finite and min < max on every axis (an unset message is the whole map).
TEST(ExportCodecTest, ARegionIsCoresBoxAndOnlyAFiniteNonEmptyOneIsTaken) {
  pb::ExportRequest request = MeshRequest();
  const absl::StatusOr<ExportSpec> whole = ExportSpecFromProto(request);
  ASSERT_TRUE(whole.ok()) << whole.status();
  EXPECT_FALSE(whole->mesh_options.region.has_value());
  EXPECT_FALSE(ExportSpecToProto(*whole).has_region());

  pb::BoundingBox* box = request.mutable_region();
  box->set_min_x(-3.0);
  box->set_min_y(-2.5);
  box->set_min_z(0.0);
  box->set_max_x(0.0);
  box->set_max_y(2.5);
  box->set_max_z(3.0);
  const absl::StatusOr<ExportSpec> spec = ExportSpecFromProto(request);
  ASSERT_TRUE(spec.ok()) << spec.status();
  ASSERT_TRUE(spec->mesh_options.region.has_value());
  EXPECT_EQ(*spec->mesh_options.region, (AxisBox{{-3.0, -2.5, 0.0}, {0.0, 2.5, 3.0}}));

  constexpr double nan = std::numeric_limits<double>::quiet_NaN();
  constexpr double inf = std::numeric_limits<double>::infinity();
  const std::vector<std::pair<std::function<void(pb::BoundingBox*)>, std::string>> bad = {
      {[](pb::BoundingBox* b) { b->set_max_x(-3.0); }, "region: min must be below max"},
      {[](pb::BoundingBox* b) { b->set_min_z(4.0); }, "region: min must be below max"},
      {[&](pb::BoundingBox* b) { b->set_min_y(nan); }, "region: coordinates must be finite"},
      {[&](pb::BoundingBox* b) { b->set_max_z(inf); }, "region: coordinates must be finite"},
      // An unset box message (all zero) is empty, not the whole map.
      {[](pb::BoundingBox* b) { b->Clear(); }, "region: min must be below max"},
  };
  for (const auto& [set, message_start] : bad) {
    pb::ExportRequest refused = request;
    set(refused.mutable_region());
    SCOPED_TRACE(refused.ShortDebugString());
    const absl::StatusOr<ExportSpec> got = ExportSpecFromProto(refused);
    ASSERT_FALSE(got.ok());
    EXPECT_EQ(got.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(std::string(got.status().message()), StartsWith(message_start));
  }
}

TEST(ExportCodecTest, TheTriangleLimitsAreCores) {
  pb::ExportRequest request = MeshRequest();
  request.set_max_triangles(kTriangleLimit);
  request.set_min_component_triangles(kTriangleLimit);
  const absl::StatusOr<ExportSpec> spec = ExportSpecFromProto(request);
  ASSERT_TRUE(spec.ok()) << spec.status();
  EXPECT_EQ(spec->mesh_options.max_triangles, kDefaultMaxMeshTriangles);
  EXPECT_EQ(spec->mesh_options.min_component_triangles, kDefaultMaxMeshTriangles);
  request.set_min_component_triangles(kTriangleLimit + 1);
  EXPECT_FALSE(ExportSpecFromProto(request).ok());
}

}  // namespace
}  // namespace plx
