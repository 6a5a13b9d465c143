// The `avp` program as a user runs it: strict numbers and lists on the command line (no
// wrap-around, no silent defaults, ranges named, outside text quoted and shortened), the limits
// (`avp limits`, `--limit`, AVP_LIMITS), outputs that never overwrite inputs and run folders that
// refuse a rerun. Each runs the built binary and checks its exit code and messages.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <avp/test/read_file.h>
#include <avp/test/run_command.h>
#include <avp/test/temp_dir_test.h>

#ifndef AVP_BINARY
#error "AVP_BINARY (the avp program under test) is not defined"
#endif

namespace avp {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

using test::Ran;

/// Runs `env avp args` through the shell, stdout and stderr together.
Ran Avp(const std::string& args, const std::string& env = "") {
  return test::RunShell(env + " '" AVP_BINARY "' " + args + " 2>&1");
}

class CliTest : public test::TempDirTest {};

TEST_F(CliTest, NegativeSeedIsRefusedNotWrapped) {
  const Ran r = Avp("run --seed -1 --print-config");
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output,
              HasSubstr("--seed '-1' must be a whole number in [0, 18446744073709551615]"));
  EXPECT_THAT(r.output, Not(HasSubstr("seed: 18446744073709551615")));
  for (const char* bad : {"0x10", "+3", "3x", "18446744073709551616", "' 7'", "1e3"}) {
    const Ran b = Avp(std::string("run --print-config --seed ") + bad);
    EXPECT_NE(b.exit_code, 0) << bad << ": " << b.output;
    EXPECT_THAT(b.output, HasSubstr("must be a whole number in [0, ")) << bad;
  }
  const Ran ok = Avp("run --print-config --seed 18446744073709551615");
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_THAT(ok.output, HasSubstr("seed: 18446744073709551615"));
}

TEST_F(CliTest, AHugeNumberIsNotEchoedWhole) {
  const std::string digits(300, '9');
  const Ran r = Avp("run --print-config --seed " + digits);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("(300 bytes)"));
  EXPECT_THAT(r.output, Not(HasSubstr(digits)));
}

TEST_F(CliTest, NumbersAreCheckedAgainstTheirRange) {
  Ran r = Avp("run --print-config --threads 100000");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("--threads '100000' must be a whole number in [0, 1024]"));
  r = Avp("run --print-config --voxel-size nan");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("--voxel-size 'nan' must be a number in [0, "));
  r = Avp("run --print-config --views 99999999999");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("--views '99999999999' must be a whole number in [0, "));
  r = Avp("run --print-config --views 5000");  // an int, then the configuration's range
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("views (5000) must be in [1, 1000]"));
  r = Avp("bench --jobs -1 --out " + (dir_ / "b").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("--jobs '-1' must be a whole number in [0, 1024]"));
  r = Avp("map build --views 0 --out " + (dir_ / "m.avpmap").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("--views '0' must be a whole number in [1, 360]"));
  r = Avp("segment --image x.png --threshold 1.5");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("--threshold '1.5' must be a number in [0, 1]"));
}

TEST_F(CliTest, EmptyListsAndZeroSeedsAreNotTheDefaults) {
  // Each would have meant "the defaults" (a whole bench); an unknown planner keeps the old code
  // from running one.
  const std::string out = " --out " + (dir_ / "bench").string();
  Ran r = Avp("bench --seeds 0 --planners nope" + out);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("--seeds (a count N for seeds 0..N-1) '0' must be a whole "
                                  "number in [1, 100000]"));
  r = Avp("bench --scenarios '' --seeds 1 --planners nope" + out);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("--scenarios '' is empty"));
  r = Avp("bench --scenarios tomato-single-cluster,,x --seeds 1 --planners nope" + out);
  EXPECT_THAT(r.output, HasSubstr("item 2 is empty"));
  r = Avp("bench --seeds 1,-1 --planners nope" + out);
  EXPECT_THAT(r.output, HasSubstr("--seeds: a seed '-1' must be a whole number"));
  r = Avp("bench --seeds 100001 --planners nope" + out);
  EXPECT_THAT(r.output, HasSubstr("must be a whole number in [1, 100000]"));
  r = Avp("bench --planners '' --seeds 1" + out);
  EXPECT_THAT(r.output, HasSubstr("--planners '' is empty"));
  EXPECT_FALSE(fs::exists(dir_ / "bench"));
}

TEST_F(CliTest, LimitsAreListedAndSet) {
  Ran r = Avp("limits");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("limit"));
  EXPECT_THAT(r.output, HasSubstr("max_file_bytes"));
  EXPECT_THAT(r.output, HasSubstr("2147483648"));
  EXPECT_THAT(r.output, HasSubstr("max_bench_episodes"));
  r = Avp("--limit max_file_bytes=5 --limit max_bench_episodes=7 limits");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("5  2147483648  bytes"));
  EXPECT_THAT(r.output, HasSubstr("(changed)"));
  r = Avp("limits", "AVP_LIMITS=max_file_bytes=6,max_bench_episodes=8");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("6  2147483648  bytes"));
  // --limit applies over the environment.
  r = Avp("--limit max_file_bytes=9 limits", "AVP_LIMITS=max_file_bytes=6");
  EXPECT_THAT(r.output, HasSubstr("9  2147483648  bytes"));
}

TEST_F(CliTest, BadLimitsNameTheBadItem) {
  Ran r = Avp("--limit max_pixels=1 limits");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("unknown limit 'max_pixels' (known: "));
  EXPECT_THAT(r.output, HasSubstr("max_file_bytes"));
  r = Avp("--limit max_file_bytes=0 limits");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("max_file_bytes"));
  r = Avp("--limit max_file_bytes limits");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("--limit 'max_file_bytes' must be one NAME=VALUE"));
  r = Avp("limits", "AVP_LIMITS='max_file_bytes=1,colour=red'");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.output, HasSubstr("AVP_LIMITS="));
  EXPECT_THAT(r.output, HasSubstr("'colour'"));
}

TEST_F(CliTest, ALimitAppliesToTheCommand) {
  const fs::path map = dir_ / "plant.avpmap";
  std::ofstream(map) << std::string(100, 'x');
  const Ran r = Avp("--limit max_file_bytes=10 map info " + map.string());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("exceeds the limit max_file_bytes = 10"));
}

TEST_F(CliTest, MapExportRefusesToOverwriteItsInput) {
  const fs::path map = dir_ / "plant.ot";
  const std::string bytes = "not a map, but mine";
  std::ofstream(map) << bytes;
  // An existing file is refused (the output rule); with --force, the input still is.
  Ran r = Avp("map export " + map.string() + " --out " + map.string());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("already exists: give another --out, or --force"));
  r = Avp("map export " + map.string() + " --out " + map.string() + " --force");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("outputs never overwrite inputs"));
  EXPECT_EQ(test::ReadWholeFile(map), bytes);
  // A folder as --out is named as one.
  r = Avp("map export " + map.string() + " --out " + dir_.string());
  EXPECT_THAT(r.output, HasSubstr("is a folder: give a file name"));
}

/// The whole number in `text` right after `key`: NumberAfter("x: 12 occupied", ": ") = 12.
size_t NumberAfter(const std::string& text, const std::string& key) {
  const size_t at = text.find(key);
  EXPECT_NE(at, std::string::npos) << key << " not in " << text;
  return at == std::string::npos ? 0 : std::stoul(text.substr(at + key.size()));
}

TEST_F(CliTest, MapExportPlyVoxelsChoosesWhatIsWritten) {
  const fs::path map = dir_ / "plant.avpmap";
  Ran r = Avp("map build --views 1 --voxel-size 0.01 --out " + map.string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const size_t occupied = NumberAfter(r.output, " known, ");
  ASSERT_GT(occupied, 0u);
  // The default: the occupied labelled voxels.
  r = Avp("map export " + map.string() + " --out " + (dir_ / "labelled.ply").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const size_t labelled = NumberAfter(r.output, "labelled.ply: ");
  ASSERT_GT(labelled, 0u);
  EXPECT_THAT(r.output, HasSubstr(" labelled voxels ("));
  // --voxels occupied: every occupied voxel, labelled ones in class colours, the others grey.
  const fs::path ply = dir_ / "occupied.ply";
  r = Avp("map export " + map.string() + " --voxels occupied --ascii --out " + ply.string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr(fmt::format(
                            "occupied.ply: {} occupied voxels, {} labelled in class colours and {} "
                            "unlabelled in grey (",
                            occupied, labelled, occupied - labelled)));
  const std::string text = test::ReadWholeFile(ply);
  EXPECT_THAT(text, HasSubstr(fmt::format("element vertex {}\n", occupied)));
  std::istringstream body(text.substr(text.find("end_header\n") + 11));
  std::string line;
  size_t vertices = 0, grey = 0;
  while (std::getline(body, line)) {
    ++vertices;
    std::istringstream fields(line);
    float x, y, z;
    int red, green, blue, cls;
    ASSERT_TRUE(fields >> x >> y >> z >> red >> green >> blue >> cls) << line;
    const bool is_grey = red == 128 && green == 128 && blue == 128;
    EXPECT_EQ(is_grey, cls == 0) << line;  // unlabelled: class 0 (background), grey
    if (is_grey) ++grey;
  }
  EXPECT_EQ(vertices, occupied);
  EXPECT_EQ(grey, occupied - labelled);
  // --all-labelled still works, as --voxels all-labelled; the two together are refused.
  r = Avp("map export " + map.string() + " --all-labelled --out " + (dir_ / "all.ply").string());
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("of them not occupied"));
  r = Avp("map export " + map.string() + " --all-labelled --voxels occupied --out " +
          (dir_ / "both.ply").string());
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("excludes"));
  r = Avp("map export " + map.string() + " --voxels everything --out " +
          (dir_ / "bad.ply").string());
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("everything not in {labelled,all-labelled,occupied}"));
  r = Avp("map export " + map.string() + " --voxels occupied --out " + (dir_ / "x.bt").string());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("--voxels occupied applies to PLY only, not to format 'bt'"));
  EXPECT_FALSE(fs::exists(dir_ / "x.bt"));
}

TEST_F(CliTest, AFolderIsNotAMissingFile) {
  const Ran r = Avp("map info " + dir_.string());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("is a folder, not a map file"));
  EXPECT_THAT(r.output, Not(HasSubstr("does not exist")));
}

TEST_F(CliTest, BenchCompareTabulatesBenchFoldersAndRunsNoBench) {
  // Two bench folders of one run each per planner, as avp bench leaves them.
  for (const char* cond : {"wet", "dry"}) {
    for (const char* planner : {"avp-nbv", "predefined"}) {
      for (int seed = 0; seed < 2; ++seed) {
        const fs::path d =
            dir_ / cond / "runs" / "plant" / planner / ("seed-" + std::to_string(seed));
        fs::create_directories(d);
        std::ofstream(d / "record.json")
            << "{\"scenario\": \"plant\", \"planner\": \"" << planner << "\", \"seed\": " << seed
            << ", \"end\": \"budget-reached\"}";
        const double f1 = (std::string(planner) == "avp-nbv" ? 0.6 : 0.4) + 0.1 * seed;
        std::ofstream(d / "metrics.csv")
            << "view,f1,fruits_found_fraction\n1,0,0\n2," << f1 << ",0.5\n";
      }
    }
  }
  const Ran r = Avp("bench compare wet dry --out table", "cd '" + dir_.string() + "' &&");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("plant"));
  EXPECT_THAT(r.output, HasSubstr("avp-nbv vs predefined     +0.200 [+0.200, +0.200]"));
  EXPECT_THAT(r.output, HasSubstr("  ahead\n"));
  EXPECT_THAT(test::ReadWholeFile(dir_ / "table" / "conditions.md"), HasSubstr("| dry |"));
  EXPECT_FALSE(fs::exists(dir_ / "out")) << "avp bench compare also ran a bench";
  const Ran bad = Avp("bench compare " + dir_.string() + " --out " + (dir_ / "t2").string());
  EXPECT_EQ(bad.exit_code, 1) << bad.output;
  EXPECT_THAT(bad.output, HasSubstr("is not an avp bench folder: it has no runs/ folder"));
  const Ran none = Avp("bench --config '" AVP_CONFIG_DIR "/experiments/paper.yaml' --conditions a");
  EXPECT_EQ(none.exit_code, 1) << none.output;
  EXPECT_THAT(none.output, HasSubstr("'a' is not a condition of the configuration (it has none)"));
}

TEST_F(CliTest, RunIntoAFolderWithResultsRefusesAtOnce) {
  const fs::path out = dir_ / "run";
  fs::create_directories(out);
  std::ofstream(out / "avp-state.json")
      << R"({"kind": "run", "state": "complete", "command": "avp run", "finished": "then"})";
  std::ofstream(out / "record.json") << "{}";
  Ran r = Avp("run --views 2 --out " + out.string());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("already holds the results of a complete avp run"));
  EXPECT_THAT(r.output, HasSubstr("--force"));
  EXPECT_EQ(test::ReadWholeFile(out / "record.json"), "{}");
  std::ofstream(out / "thesis.tex") << "mine";
  r = Avp("run --views 2 --force --out " + out.string());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("so --force does not empty it"));
  EXPECT_EQ(test::ReadWholeFile(out / "thesis.tex"), "mine");
}

TEST_F(CliTest, MisspeltNamesGetTheNearestOne) {
  Ran r = Avp("rendr --scenario tomato-single-cluster");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_THAT(r.output, HasSubstr("unknown command 'rendr'; did you mean 'render'?"));
  r = Avp("map biuld --out x.avpmap");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_THAT(r.output, HasSubstr("unknown command 'biuld'; did you mean 'build'?"));
  r = Avp("run --print-config --set episode.view=6");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("did you mean 'episode.views'?"));
  r = Avp("run --print-config --planner-option p_unkown=0.1");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("did you mean 'p_unknown'?"));
  r = Avp("run --print-config --planner avp-nvb");
  EXPECT_THAT(r.output, HasSubstr("did you mean 'avp-nbv'?"));
  r = Avp("run --print-config --scenario tomato-single-clustr");
  EXPECT_THAT(r.output, HasSubstr("did you mean 'tomato-single-cluster'?"));
  // Far from every name: no guess.
  r = Avp("run --print-config --planner zzzzzzzz");
  EXPECT_THAT(r.output, Not(HasSubstr("did you mean")));
}

TEST_F(CliTest, HelpNamesACommand) {
  Ran r = Avp("help");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("render"));
  r = Avp("help map build");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("--voxel-size"));
  r = Avp("help mapp");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_THAT(r.output, HasSubstr("did you mean 'map'?"));
}

TEST_F(CliTest, HelpIsAcceptedWhereANameIsExpected) {
  for (const char* args : {"run --scenario help", "bench --scenarios help"}) {
    const Ran r = Avp(args);
    EXPECT_EQ(r.exit_code, 0) << args << ": " << r.output;
    EXPECT_THAT(r.output, HasSubstr("tomato-full-occlusion")) << args;
  }
  Ran r = Avp("bench --planners help");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("reference-nbv"));
  r = Avp("bench --segmenter help");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("oracle"));
}

TEST_F(CliTest, UnknownOptionsGetTheNearestOneAndTheCommandThatHasThem) {
  Ran r = Avp("run --seeds 3 --print-config");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_THAT(r.output, HasSubstr("avp run: unknown option '--seeds'; did you mean '--seed'? "
                                  "(--seeds is an option of avp bench)"));
  r = Avp("run --print-config --seed 3 4");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_THAT(r.output, HasSubstr("avp run: unexpected argument '4'"));
  r = Avp("serve");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_THAT(r.output, HasSubstr("avp serve: a command is required: segmentation, models"));
}

TEST_F(CliTest, RunAndBenchShareSpellingsAndOptions) {
  // avp run takes bench's plural spellings for one name, and sends several to avp bench.
  Ran r = Avp("run --print-config --planners predefined --scenarios tomato-single-cluster");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("name: predefined"));
  r = Avp("run --print-config --planners avp-nbv,predefined");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("avp bench --planners avp-nbv,predefined runs each of them"));
  // avp bench takes run's singular spellings and every episode flag run has.
  const Ran help = Avp("help bench");
  for (const char* flag :
       {"--scenarios,--scenario", "--planners,--planner", "--seed ", "--voxel-size", "--prompt",
        "--policy", "--carving", "--segmenter-option", "--map-option", "--no-noise",
        "--oracle-regret", "--set"}) {
    EXPECT_THAT(help.output, HasSubstr(flag)) << flag;
  }
  const fs::path out = dir_ / "bench";
  r =
      Avp("bench --planner predefined --scenario tomato-single-cluster --seed 4 --views 1 "
          "--voxel-size 0.01 --no-noise --prompt tomato --jobs 1 --out " +
          out.string());
  EXPECT_EQ(r.exit_code, 0) << r.output;
  const std::string md = test::ReadWholeFile(out / "summary.md");
  EXPECT_THAT(md, HasSubstr("1 seed(s)"));
  EXPECT_THAT(md, HasSubstr("10 mm voxels"));
  EXPECT_THAT(md, HasSubstr("`depth_noise.enabled = false`"));
  EXPECT_TRUE(fs::exists(out / "runs/tomato-single-cluster/predefined/seed-4/record.json"));
  // --seed is the seeds themselves, --seeds a count: both at once is refused.
  r = Avp("bench --seed 4 --seeds 2 --out " + (dir_ / "b2").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("--seeds and --seed both given"));
}

TEST_F(CliTest, LimitsAndListsAnywhereOnTheLine) {
  // --limit after the command, as before it.
  Ran r = Avp("run --print-config --limit max_yaml_bytes=1000000");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  r = Avp("run --print-config --limit nope=1");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("unknown limit 'nope'"));
  // A list with spaces, negative numbers included, as with commas.
  const fs::path out = dir_ / "render";
  r = Avp("render --scenario tomato-single-cluster --joints 0 -70 60 0 47.5 0 --no-noise --out " +
          out.string());
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(fs::exists(out / "rgb.png"));
}

TEST_F(CliTest, PerComponentHelpAndSubnormalNumbers) {
  Ran r = Avp("run --planner help");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("`--planner help:NAME` lists one's options"));
  EXPECT_THAT(r.output, Not(HasSubstr("ray_stride_px")));
  r = Avp("run --planner help:avp-nbv");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("ray_stride_px=20"));
  r = Avp("bench --segmenter help:orcale");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_THAT(r.output, HasSubstr("did you mean 'oracle'?"));
  // 1e-320 is a (subnormal) number, not "not a finite number".
  r = Avp("run --print-config --planner-option p_unknown=1e-320");
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

TEST_F(CliTest, ConfigurationErrorsAreFoundBeforeAnythingIsWritten) {
  // A model folder that is not there: refused before the run folder exists.
  const fs::path out = dir_ / "ywes";
  Ran r = Avp("run --segmenter ywes://" + (dir_ / "no-models").string() + " --out " + out.string());
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("no-models"));
  EXPECT_FALSE(fs::exists(out)) << r.output;
  // A segmentation service naming a segmenter that does not exist does not start.
  r = Avp("serve segmentation --port 0 --backend orcale");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_THAT(r.output, HasSubstr("--backend 'orcale': unknown segmenter 'orcale'"));
  EXPECT_THAT(r.output, HasSubstr("did you mean 'oracle'?"));
  // A file of another kind is named by what it is.
  r = Avp("scene check " + std::string(AVP_SOURCE_DIR) + "/configs/scenes/example_plant.obj");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, HasSubstr("is a Wavefront OBJ mesh, not a YAML file"));
}

TEST_F(CliTest, RecordCompressionIsNamedAndNeedsARecording) {
  Ran r = Avp("run --print-config --record-compression zstd");
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("--record-compression requires --record"));
  r = Avp("run --print-config --record --record-compression bz2");
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("bz2"));
  EXPECT_THAT(r.output, HasSubstr("lz4"));
  r = Avp("bench --record --record-compression lz4 --planners help");
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

TEST_F(CliTest, MapFilesAreReplacedOnlyWithForce) {
  const fs::path gt = dir_ / "gt.bt";
  const std::string args =
      "map gt --scenario tomato-single-cluster --voxel-size 0.01 --out " + gt.string();
  ASSERT_EQ(Avp(args).exit_code, 0);
  const Ran again = Avp(args);
  EXPECT_EQ(again.exit_code, 1) << again.output;
  EXPECT_THAT(again.output, HasSubstr("already exists: give another --out, or --force"));
  EXPECT_EQ(Avp(args + " --force").exit_code, 0);
}

}  // namespace
}  // namespace avp
