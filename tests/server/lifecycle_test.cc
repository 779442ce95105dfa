// Map lifecycle over the wire: CreateMap / GetMap / ListMaps / DeleteMap / SaveMap / LoadMap,
// their argument checks and their error codes.
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/server/daemon_fixture.h"

namespace plx::server::testing {
namespace {

class LifecycleTest : public ::testing::Test {
 protected:
  void SetUp() override {
    DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_life"));
    o.max_maps = 3;
    absl::StatusOr<std::unique_ptr<TestDaemon>> d = StartTestDaemon(o);
    ASSERT_TRUE(d.ok()) << d.status();
    d_ = std::move(*d);
  }
  pb::Plenoxd::Stub& stub() { return *d_->stub; }

  std::unique_ptr<TestDaemon> d_;
};

TEST_F(LifecycleTest, CreateReportsTheNewEmptyMap) {
  pb::MapInfo info;
  const grpc::Status s = CreateMap(stub(), "kitchen-1.v2_a", 0.05f, &info);
  ASSERT_TRUE(s.ok()) << Describe(s);
  EXPECT_EQ(info.name(), "kitchen-1.v2_a");
  EXPECT_FLOAT_EQ(info.voxel_size(), 0.05f);
  EXPECT_EQ(info.bricks(), 0u);
  EXPECT_EQ(info.keyframes(), 0u);
  EXPECT_FALSE(info.dirty());
  EXPECT_FALSE(info.mapping());
  EXPECT_GE(info.version(), 1u);

  pb::MapInfo got;
  ASSERT_TRUE(GetMap(stub(), "kitchen-1.v2_a", &got).ok());
  EXPECT_EQ(got.name(), info.name());
  EXPECT_EQ(got.version(), info.version());
  EXPECT_FLOAT_EQ(got.voxel_size(), 0.05f);
}

TEST_F(LifecycleTest, VoxelSizeZeroMeansTheDefault) {
  pb::MapInfo info;
  ASSERT_TRUE(CreateMap(stub(), "default_voxel", 0.0f, &info).ok());
  EXPECT_FLOAT_EQ(info.voxel_size(), 0.02f);
}

TEST_F(LifecycleTest, BadNamesAreInvalidArgumentNamingTheField) {
  const std::vector<std::string> bad = {"",          ".hidden",        "a/b",  "../escape",
                                        "with space", std::string(65, 'x'), "tab\t",
                                        "uml\xc3\xa4ut", "semi;colon"};
  for (const std::string& name : bad) {
    const grpc::Status s = CreateMap(stub(), name);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << "\"" << name << "\"";
    EXPECT_NE(s.error_message().find("name"), std::string::npos) << s.error_message();
  }
  // 64 characters is the longest valid name.
  EXPECT_TRUE(CreateMap(stub(), std::string(64, 'y')).ok());
  // Nothing was created by the rejected calls.
  grpc::ClientContext context;
  Prepare(&context);
  pb::ListMapsResponse list;
  ASSERT_TRUE(stub().ListMaps(&context, pb::ListMapsRequest(), &list).ok());
  ASSERT_EQ(list.maps_size(), 1);
  EXPECT_EQ(list.maps(0).name(), std::string(64, 'y'));
}

TEST_F(LifecycleTest, BadVoxelSizeIsInvalidArgumentNamingTheField) {
  for (float voxel : {0.0001f, 2.0f, INFINITY}) {
    const grpc::Status s = CreateMap(stub(), "v", voxel);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << voxel;
    EXPECT_NE(s.error_message().find("voxel_size"), std::string::npos) << s.error_message();
  }
}

// The proto says "0 = the default (0.02)"; a negative or NaN voxel size is not 0 and must be
// rejected like any other out-of-range size.
TEST_F(LifecycleTest, NegativeOrNanVoxelSizeIsInvalidArgument) {
  const float bad[] = {-0.1f, -1.0f, std::nanf(""), -INFINITY};
  for (float voxel : bad) {
    pb::MapInfo info;
    const grpc::Status s = CreateMap(stub(), "v", voxel, &info);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
        << voxel << " was accepted as voxel size " << info.voxel_size();
    EXPECT_NE(s.error_message().find("voxel_size"), std::string::npos) << s.error_message();
    if (s.ok()) {
      grpc::ClientContext context;
      Prepare(&context);
      pb::DeleteMapRequest del;
      del.set_name("v");
      pb::DeleteMapResponse r;
      ASSERT_TRUE(stub().DeleteMap(&context, del, &r).ok());
    }
  }
}

TEST_F(LifecycleTest, DuplicateIsAlreadyExists) {
  ASSERT_TRUE(CreateMap(stub(), "twin").ok());
  const grpc::Status s = CreateMap(stub(), "twin", 0.1f);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::ALREADY_EXISTS) << Describe(s);
  // The original is untouched.
  pb::MapInfo info;
  ASSERT_TRUE(GetMap(stub(), "twin", &info).ok());
  EXPECT_FLOAT_EQ(info.voxel_size(), kVoxel);
}

TEST_F(LifecycleTest, MaxMapsIsResourceExhaustedUntilOneIsDeleted) {
  for (const char* name : {"m1", "m2", "m3"}) ASSERT_TRUE(CreateMap(stub(), name).ok()) << name;
  const grpc::Status s = CreateMap(stub(), "m4");
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << Describe(s);

  grpc::ClientContext context;
  Prepare(&context);
  pb::DeleteMapRequest del;
  del.set_name("m2");
  pb::DeleteMapResponse deleted;
  ASSERT_TRUE(stub().DeleteMap(&context, del, &deleted).ok());
  EXPECT_TRUE(CreateMap(stub(), "m4").ok());
}

TEST_F(LifecycleTest, ListMapsListsEveryMapByName) {
  for (const char* name : {"b", "a", "c"}) ASSERT_TRUE(CreateMap(stub(), name).ok());
  grpc::ClientContext context;
  Prepare(&context);
  pb::ListMapsResponse list;
  ASSERT_TRUE(stub().ListMaps(&context, pb::ListMapsRequest(), &list).ok());
  std::vector<std::string> names;
  for (const pb::MapInfo& m : list.maps()) names.push_back(m.name());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"a", "b", "c"}));
}

TEST_F(LifecycleTest, UnknownMapsAreNotFound) {
  pb::MapInfo info;
  EXPECT_EQ(GetMap(stub(), "nope", &info).error_code(), grpc::StatusCode::NOT_FOUND);
  {
    grpc::ClientContext context;
    Prepare(&context);
    pb::DeleteMapRequest del;
    del.set_name("nope");
    pb::DeleteMapResponse r;
    EXPECT_EQ(stub().DeleteMap(&context, del, &r).error_code(), grpc::StatusCode::NOT_FOUND);
  }
  EXPECT_EQ(SaveMap(stub(), "nope").error_code(), grpc::StatusCode::NOT_FOUND);
  {
    grpc::ClientContext context;
    Prepare(&context);
    pb::LoadMapRequest load;
    load.set_name("nope");
    pb::MapInfo r;
    EXPECT_EQ(stub().LoadMap(&context, load, &r).error_code(), grpc::StatusCode::NOT_FOUND);
  }
  {
    // A name that is not a map name at all never reaches the file system.
    grpc::ClientContext context;
    Prepare(&context);
    pb::LoadMapRequest load;
    load.set_name("../../etc/passwd");
    pb::MapInfo r;
    const grpc::Status s = stub().LoadMap(&context, load, &r);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << Describe(s);
    EXPECT_NE(s.error_message().find("name"), std::string::npos) << s.error_message();
  }
}

TEST_F(LifecycleTest, DeleteRemovesTheMapAndItsFile) {
  ASSERT_TRUE(CreateMap(stub(), "gone").ok());
  pb::MapInfo saved;
  const grpc::Status s = SaveMap(stub(), "gone", &saved);
  ASSERT_TRUE(s.ok()) << Describe(s);
  EXPECT_FALSE(saved.dirty());
  const std::filesystem::path file = std::filesystem::path(d_->data_dir) / "gone.plx";
  ASSERT_TRUE(std::filesystem::exists(file));

  grpc::ClientContext context;
  Prepare(&context);
  pb::DeleteMapRequest del;
  del.set_name("gone");
  pb::DeleteMapResponse r;
  ASSERT_TRUE(stub().DeleteMap(&context, del, &r).ok());
  pb::MapInfo info;
  EXPECT_EQ(GetMap(stub(), "gone", &info).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_FALSE(std::filesystem::exists(file));
  // The name is free again.
  EXPECT_TRUE(CreateMap(stub(), "gone").ok());
}

TEST_F(LifecycleTest, SaveThenLoadRoundTrips) {
  ASSERT_TRUE(CreateMap(stub(), "disk", 0.08f).ok());
  ASSERT_TRUE(SaveMap(stub(), "disk").ok());
  grpc::ClientContext context;
  Prepare(&context);
  pb::LoadMapRequest load;
  load.set_name("disk");
  pb::MapInfo loaded;
  const grpc::Status s = stub().LoadMap(&context, load, &loaded);
  ASSERT_TRUE(s.ok()) << Describe(s);
  EXPECT_EQ(loaded.name(), "disk");
  EXPECT_FLOAT_EQ(loaded.voxel_size(), 0.08f);
  EXPECT_FALSE(loaded.dirty());
}

// A second daemon asked to listen on a port that is already serving must fail to start
// ("cannot listen on ...") rather than share the port with the first.
TEST(LifecyclePortTest, ListenPortInUseFailsToStart) {
  absl::StatusOr<std::unique_ptr<TestDaemon>> first =
      StartTestDaemon(TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_port1")));
  ASSERT_TRUE(first.ok()) << first.status();
  DaemonOptions o = TestDaemonOptions(plx::testing::MakeTempDir("plx_srv_port2"));
  o.listen = "127.0.0.1:" + std::to_string((*first)->daemon->port());
  absl::StatusOr<std::unique_ptr<Daemon>> second = Daemon::Start(o);
  EXPECT_FALSE(second.ok()) << "a second daemon started on port " << (*first)->daemon->port();
  if (second.ok()) (*second)->Drain(absl::Seconds(0)).IgnoreError();
}

// Without a data directory nothing can be saved: FAILED_PRECONDITION, not a crash or OK.
TEST(LifecycleNoDataDirTest, SaveIsFailedPrecondition) {
  DaemonOptions o = TestDaemonOptions("");
  absl::StatusOr<std::unique_ptr<TestDaemon>> d = StartTestDaemon(o);
  ASSERT_TRUE(d.ok()) << d.status();
  ASSERT_TRUE(CreateMap(*(*d)->stub, "m").ok());
  EXPECT_EQ(SaveMap(*(*d)->stub, "m").error_code(), grpc::StatusCode::FAILED_PRECONDITION);
}

}  // namespace
}  // namespace plx::server::testing
