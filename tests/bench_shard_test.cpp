// avp bench --shard K/N, avp bench merge and avp bench --resume (experiment::RunBench,
// experiment::MergeBenches): a tiny real bench, 2 scenarios x 2 planners x 2 seeds x 2 views, run
// whole, in shards and interrupted; the merged and the resumed summaries equal the whole one to
// the byte, and every bad merge or resume is refused naming what is wrong.
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <avp/experiment/bench.h>
#include <avp/experiment/output_folder.h>
#include <avp/report/conditions.h>
#include <avp/test/read_file.h>
#include <avp/test/temp_dir_test.h>

namespace avp::experiment {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using Job = std::tuple<std::string, std::string, uint64_t>;

std::string Slurp(const fs::path& p) { return test::ReadWholeFile(p); }

nlohmann::json ReadJson(const fs::path& p) { return nlohmann::json::parse(Slurp(p)); }

/// The run folders under dir/runs, as (scenario, planner, seed).
std::set<Job> Runs(const fs::path& dir) {
  std::set<Job> out;
  for (const auto& s : fs::directory_iterator(dir / "runs")) {
    for (const auto& p : fs::directory_iterator(s.path())) {
      for (const auto& r : fs::directory_iterator(p.path())) {
        out.emplace(s.path().filename().string(), p.path().filename().string(),
                    std::stoull(r.path().filename().string().substr(5)));
      }
    }
  }
  return out;
}

class BenchShardTest : public test::TempDirTest {
 protected:
  BenchConfig Config(const fs::path& out) const {
    BenchConfig o;
    o.scenarios = {"tomato-single-cluster", "tomato-full-occlusion"};
    o.planners = {"random", "predefined"};
    o.seeds = {0, 1};
    o.base.episode.views = 2;
    o.out_dir = out;
    o.progress = false;
    o.jobs = 2;
    return o;
  }
  /// The whole bench, run once for the test suite's cases that compare with it.
  const fs::path& Whole() {
    const fs::path out = dir_ / "whole";
    if (!fs::exists(out / "summary.csv")) {
      const Result<BenchSummary> r = RunBench(Config(out), registries_);
      EXPECT_TRUE(r.ok()) << r.status().ToString();
      EXPECT_EQ(r->episodes, 8u);
      EXPECT_EQ(r->failed, 0u);
      EXPECT_EQ(r->resumed, 0u);
    }
    whole_ = out;
    return whole_;
  }
  const Registries registries_ = BuiltinRegistries();
  fs::path whole_;
};

TEST_F(BenchShardTest, ShardsMergeIntoTheSummaryOfTheWholeBench) {
  const fs::path whole = Whole();
  const nlohmann::json manifest = ReadJson(whole / "bench.json");
  EXPECT_EQ(manifest["jobs"].size(), 8u);
  EXPECT_EQ(manifest["shard"]["count"], 1);
  EXPECT_EQ(manifest["ground_truth"].size(), 4u);  // 2 scenarios x 2 seeds

  std::vector<fs::path> shards;
  std::set<Job> seen;
  size_t total = 0, ground_truths = 0;
  for (uint64_t k = 1; k <= 2; ++k) {
    BenchConfig c = Config(dir_ / fmt::format("shard-{}", k));
    c.shard_index = k;
    c.shard_count = 2;
    const Result<BenchSummary> r = RunBench(c, registries_);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    // A shard writes its runs and bench.json, no summary.
    EXPECT_TRUE(r->files.empty());
    EXPECT_FALSE(fs::exists(c.out_dir / "summary.csv"));
    const std::set<Job> runs = Runs(c.out_dir);
    EXPECT_EQ(runs.size(), r->episodes);
    // (scenario, seed)s are dealt whole: each of the shard's has both planners' runs, and its
    // ground truth was computed here only.
    std::set<std::pair<std::string, uint64_t>> groups;
    for (const Job& j : runs) groups.emplace(std::get<0>(j), std::get<2>(j));
    EXPECT_EQ(runs.size(), 2 * groups.size()) << "shard " << k;
    EXPECT_GE(groups.size(), 1u) << "shard " << k;
    for (const Job& j : runs) EXPECT_TRUE(seen.insert(j).second) << "a job in two shards";
    total += runs.size();
    // The same job list as the whole bench's, and the ground truth of its own groups only.
    const nlohmann::json m = ReadJson(c.out_dir / "bench.json");
    EXPECT_EQ(m["jobs"], manifest["jobs"]);
    EXPECT_EQ(m["shard"]["index"], k);
    EXPECT_EQ(m["ground_truth"].size(), groups.size());
    ground_truths += m["ground_truth"].size();
    shards.push_back(c.out_dir);
  }
  EXPECT_EQ(total, 8u);
  EXPECT_EQ(ground_truths, 4u);  // each (scenario, seed) once, in one shard
  EXPECT_EQ(seen, Runs(whole));

  const fs::path merged = dir_ / "merged";
  const Result<BenchSummary> m = MergeBenches(shards, merged, false, false);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->episodes, 8u);
  EXPECT_EQ(m->failed, 0u);
  EXPECT_EQ(Runs(merged), Runs(whole));
  for (const char* f : {"summary.csv", "fruits_by_visibility.csv"}) {
    EXPECT_EQ(Slurp(merged / f), Slurp(whole / f)) << f;
  }
  EXPECT_TRUE(fs::is_regular_file(merged / "report.html"));
  EXPECT_TRUE(fs::is_regular_file(merged / "summary.md"));
  const Result<FolderState> state = ReadFolderState(merged);
  ASSERT_TRUE(state.ok());
  EXPECT_EQ(state->state, "complete");
  const nlohmann::json mm = ReadJson(merged / "bench.json");
  EXPECT_EQ(mm["ground_truth"], manifest["ground_truth"]);
  EXPECT_EQ(mm["bench"], manifest["bench"]);
  EXPECT_EQ(mm["merged_from"].size(), 2u);

  // Refused, naming what is wrong.
  const auto merge_error = [&](const std::vector<fs::path>& dirs, const fs::path& out) {
    const Result<BenchSummary> r = MergeBenches(dirs, out, false, false);
    EXPECT_FALSE(r.ok());
    return r.ok() ? std::string() : r.status().ToString();
  };
  EXPECT_THAT(merge_error({shards[0]}, dir_ / "m1"),
              AllOf(HasSubstr("jobs are in no shard"), HasSubstr("shards 2 of 2 are not given")));
  EXPECT_THAT(merge_error({shards[0], shards[0]}, dir_ / "m2"),
              HasSubstr("shard 1/2 is given twice"));
  EXPECT_THAT(merge_error({shards[0], shards[1]}, shards[0] / "out"),
              HasSubstr("lie one inside the other"));
  EXPECT_THAT(merge_error({shards[0], whole}, dir_ / "m3"), HasSubstr("the shard count"));
  EXPECT_THAT(merge_error({shards[0], shards[1]}, merged), HasSubstr("already holds"));
  EXPECT_THAT(merge_error({dir_ / "nothing"}, dir_ / "m4"), HasSubstr("has no bench.json"));
  EXPECT_THAT(merge_error({}, dir_ / "m5"), HasSubstr("no shard"));
  // A shard that did not finish is not merged.
  {
    std::string s = Slurp(shards[1] / "avp-state.json");
    s.replace(s.find("complete"), 8, "in-progress");
    std::ofstream(shards[1] / "avp-state.json") << s;
    EXPECT_THAT(merge_error({shards[0], shards[1]}, dir_ / "m6"),
                AllOf(HasSubstr("in-progress"), HasSubstr("--resume")));
  }
  // Shards of another bench (another view budget).
  BenchConfig other = Config(dir_ / "other");
  other.base.episode.views = 1;
  other.shard_index = 2;
  other.shard_count = 2;
  ASSERT_TRUE(RunBench(other, registries_).ok());
  EXPECT_THAT(merge_error({shards[0], other.out_dir}, dir_ / "m7"),
              AllOf(HasSubstr("not of one bench"), HasSubstr("views")));
}

TEST_F(BenchShardTest, ResumeRunsOnlyWhatDidNotFinish) {
  const fs::path whole = Whole();
  const fs::path out = dir_ / "resumed";
  fs::copy(whole, out, fs::copy_options::recursive);
  // Killed half-way: the bench in progress, no summary, one run unfinished, one never started.
  const fs::path unfinished = out / "runs/tomato-full-occlusion/random/seed-1";
  const fs::path unstarted = out / "runs/tomato-single-cluster/predefined/seed-0";
  for (const fs::path& d : {out, unfinished}) {
    std::string s = Slurp(d / "avp-state.json");
    s.replace(s.find("complete"), 8, "in-progress");
    std::ofstream(d / "avp-state.json") << s;
  }
  fs::remove(unfinished / "record.json");
  fs::remove_all(unstarted);
  fs::remove(out / "summary.csv");
  const fs::path kept = out / "runs/tomato-single-cluster/random/seed-1/record.json";
  const std::string kept_record = Slurp(kept);

  BenchConfig c = Config(out);
  // Without --resume the folder is refused, as any folder holding results.
  EXPECT_THAT(RunBench(c, registries_).status().ToString(), HasSubstr("give another --out"));
  c.resume = true;
  const Result<BenchSummary> r = RunBench(c, registries_);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->episodes, 8u);
  EXPECT_EQ(r->resumed, 6u);
  EXPECT_EQ(Slurp(kept), kept_record);  // read back, not run again
  EXPECT_TRUE(fs::is_regular_file(unfinished / "record.json"));
  EXPECT_TRUE(fs::is_regular_file(unstarted / "record.json"));
  for (const char* f : {"summary.csv", "fruits_by_visibility.csv"}) {
    EXPECT_EQ(Slurp(out / f), Slurp(whole / f)) << f;
  }
  EXPECT_EQ(ReadFolderState(out)->state, "complete");

  // Resuming a complete bench runs nothing.
  const Result<BenchSummary> again = RunBench(c, registries_);
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_EQ(again->resumed, 8u);

  // Another bench in the folder is refused, naming what differs.
  BenchConfig more = c;
  more.seeds = {0, 1, 2};
  EXPECT_THAT(RunBench(more, registries_).status().ToString(),
              AllOf(HasSubstr("cannot resume"), HasSubstr("seeds")));
  BenchConfig shard = c;
  shard.shard_index = 1;
  shard.shard_count = 2;
  EXPECT_THAT(RunBench(shard, registries_).status().ToString(), HasSubstr("the shard count"));
  // A folder without bench.json, --resume with --force, a shard out of range.
  fs::create_directories(dir_ / "foreign");
  std::ofstream(dir_ / "foreign" / "notes.txt") << "mine";
  BenchConfig foreign = Config(dir_ / "foreign");
  foreign.resume = true;
  EXPECT_THAT(RunBench(foreign, registries_).status().ToString(), HasSubstr("has no bench.json"));
  BenchConfig both = c;
  both.force = true;
  EXPECT_THAT(RunBench(both, registries_).status().ToString(), HasSubstr("give one"));
  BenchConfig range = Config(dir_ / "range");
  range.shard_index = 3;
  range.shard_count = 2;
  EXPECT_THAT(RunBench(range, registries_).status().ToString(), HasSubstr("the shard 3/2"));
  // A missing folder with --resume starts afresh.
  BenchConfig fresh = Config(dir_ / "fresh");
  fresh.resume = true;
  fresh.shard_index = 2;
  fresh.shard_count = 8;
  const Result<BenchSummary> f = RunBench(fresh, registries_);
  ASSERT_TRUE(f.ok()) << f.status().ToString();
  EXPECT_EQ(f->episodes, 2u);  // 4 (scenario, seed)s over 8 shards: one, or none, each
  EXPECT_EQ(f->resumed, 0u);
}

TEST_F(BenchShardTest, RunFoldersAreReadBackWholeOrRefused) {
  const fs::path whole = Whole();
  const fs::path run = whole / "runs/tomato-full-occlusion/random/seed-0";
  const Result<report::BenchEpisode> e =
      report::ReadBenchEpisode(run, "tomato-full-occlusion", "random", 0);
  ASSERT_TRUE(e.ok()) << e.status().ToString();
  EXPECT_TRUE(e->status.ok());
  EXPECT_EQ(e->metrics.size(), 2u);  // 2 views
  ASSERT_FALSE(e->metrics.empty());
  EXPECT_EQ(e->metrics[0].front().first, "f1");
  EXPECT_EQ(e->plan_ms.size(), 1u);  // one plan between two views
  EXPECT_GT(e->episode_s, 0.0);
  EXPECT_FALSE(e->fruits.empty());
  // Not the run it should be.
  EXPECT_THAT(
      report::ReadBenchEpisode(run, "tomato-full-occlusion", "random", 1).status().ToString(),
      HasSubstr("where tomato-full-occlusion / random / seed 1 belongs"));
  // A damaged metrics file names the file and the row.
  const fs::path copy = dir_ / "copy";
  fs::copy(run, copy);
  {
    std::string s = Slurp(copy / "metrics.csv");
    // The last row's first metric (f1) is no number.
    s.insert(s.find(',', s.rfind('\n', s.size() - 2)) + 1, "x");
    std::ofstream(copy / "metrics.csv") << s;
  }
  EXPECT_THAT(
      report::ReadBenchEpisode(copy, "tomato-full-occlusion", "random", 0).status().ToString(),
      AllOf(HasSubstr("metrics.csv"), HasSubstr("row 3")));
  // An unfinished run comes back failed, with its state.
  fs::remove_all(copy);
  fs::copy(run, copy);
  {
    std::string s = Slurp(copy / "avp-state.json");
    s.replace(s.find("complete"), 8, "in-progress");
    std::ofstream(copy / "avp-state.json") << s;
  }
  const Result<report::BenchEpisode> u =
      report::ReadBenchEpisode(copy, "tomato-full-occlusion", "random", 0);
  ASSERT_TRUE(u.ok());
  EXPECT_THAT(u->status.ToString(), HasSubstr("state in-progress"));
}

}  // namespace
}  // namespace avp::experiment
