// avp sim ros2: the simulator as a ROS 2 robot (docs/ros2.md): the scene of a run configuration
// rendered as a RealSense would publish it, the arm's joint states and TF, obeying
// JointTrajectory goals, until Ctrl-C or --duration.
#include <cstdio>
#include <memory>
#include <stop_token>
#include <string>
#include <vector>

#include <fmt/format.h>

#include <avp/experiment/episode_runner.h>
#include <avp/io/options_yaml.h>
#include <avp/robot/arm_model.h>
#include <avp/ros/live/live_options.h>
#include <avp/ros/simrobot/sim_ros2_robot.h>

#include "cli_common.h"
#include "ros2_cli.h"
#include "run_cli.h"

namespace avp::apps {

namespace {

struct SimCli {
  RunCli run;
  std::vector<std::string> sim_options;
  std::string node_name = "avp_sim";
  int domain_id = -1;
  std::string distro = "humble";
  double duration_s = 0.0;
};

int SimRos2(const CLI::App& cmd, const SimCli& cli, const experiment::Registries& registries) {
  YAML::Node section;
  const Result<experiment::CheckedRunConfig> config =
      ResolveConfig(cmd, cli.run, registries, {.name = "sim", .node = &section});
  if (!config.ok()) return Failed("sim ros2", config.status());
  const Result<ros::simrobot::SimRobotOptions> options =
      ResolveSectionOptions(ros::simrobot::SimRobotOptionTable(), section, cli.sim_options,
                            cli.run.config_file + ": sim", "sim option");
  if (!options.ok()) return Failed("sim ros2", options.status());
  if (!(cli.duration_s >= 0.0 && cli.duration_s <= 1e7)) {
    return Failed("sim ros2",
                  InvalidArgumentError(fmt::format(
                      "--duration {} must be in [0, 1e7] s (0: until Ctrl-C)", cli.duration_s)));
  }
  if (cli.distro != "humble" && cli.distro != "jazzy") {
    return Failed("sim ros2", InvalidArgumentError(fmt::format(
                                  "--distro '{}' must be humble or jazzy", cli.distro)));
  }
  if (cli.run.print_config) {
    Result<YAML::Node> yaml = experiment::RunConfigToYaml(**config, registries);
    if (!yaml.ok()) return Failed("sim ros2", yaml.status());
    (*yaml)["sim"] = io::OptionsToYaml(ros::simrobot::SimRobotOptionTable().Values(*options),
                                       ros::simrobot::SimRobotOptionTable().Info(*options));
    std::fputs(io::YamlText(*yaml).c_str(), stdout);
    return 0;
  }
  Result<sim::Scene> scene = experiment::LoadScene(**config, registries);
  if (!scene.ok()) return Failed("sim ros2", scene.status());
  Result<robot::ArmModel> model = robot::LoadDefaultArm();
  if (!model.ok()) return Failed("sim ros2", model.status());
  ros::dds::NodeOptions node_options;
  node_options.name = cli.node_name;
  node_options.domain_id = cli.domain_id;
  node_options.distro =
      cli.distro == "jazzy" ? ros::msg::RosDistro::kJazzy : ros::msg::RosDistro::kHumble;
  Result<std::unique_ptr<ros::dds::Node>> node = ros::dds::Node::Create(node_options);
  if (!node.ok()) return Failed("sim ros2", node.status());
  Result<std::unique_ptr<ros::simrobot::SimRos2Robot>> robot = ros::simrobot::SimRos2Robot::Create(
      **node, *scene, *model, experiment::StartJoints(*scene, *model), (*config)->camera,
      (*config)->depth_noise, (*config)->seed, *options);
  if (!robot.ok()) return Failed("sim ros2", robot.status());

  std::printf(
      "avp sim ros2: %s (seed %llu) as node %s on ROS_DOMAIN_ID %d: publishing %s, %s, %s, "
      "/tf, /tf_static and %s; obeying %s. Ctrl-C stops.\n",
      scene->name.c_str(), static_cast<unsigned long long>((*config)->seed),
      (*node)->fully_qualified_name().c_str(), (*node)->domain_id(), options->color_topic.c_str(),
      options->depth_topic.c_str(), options->camera_info_topic.c_str(),
      options->joint_states_topic.c_str(), options->trajectory_topic.c_str());
  std::fflush(stdout);
  std::stop_source stop;
  ros::simrobot::SimRos2Robot* r = robot->get();
  uint64_t arrivals = 0, refused = 0;
  Status s = Status::Ok();
  {
    // Progress: a line per arrival and per refused goal.
    StopOnSignal stopper(stop, cli.duration_s, "avp sim ros2: stopping", [&] {
      const ros::simrobot::SimRobotCounters c = r->counters();
      if (c.arrivals != arrivals) {
        arrivals = c.arrivals;
        std::printf("arrived at goal %llu (%llu frames rendered, %llu image sets published)\n",
                    static_cast<unsigned long long>(arrivals),
                    static_cast<unsigned long long>(c.frames_rendered),
                    static_cast<unsigned long long>(c.images_published));
        std::fflush(stdout);
      }
      if (c.goals_refused != refused) {
        refused = c.goals_refused;
        std::printf("%s\n", c.last_problem.c_str());
        std::fflush(stdout);
      }
    });
    s = r->Run(stop.get_token());
  }
  if (!s.ok()) return Failed("sim ros2", s);
  const ros::simrobot::SimRobotCounters c = r->counters();
  std::printf("avp sim ros2: stopped after %llu goals (%llu refused), %llu frames rendered\n",
              static_cast<unsigned long long>(c.goals_received),
              static_cast<unsigned long long>(c.goals_refused),
              static_cast<unsigned long long>(c.frames_rendered));
  return 0;
}

}  // namespace

void AddSimCommand(CLI::App& app, CommandContext& context) {
  CLI::App* sim = app.add_subcommand("sim", "The simulator behind robot interfaces");
  sim->require_subcommand(1);
  auto cli = std::make_shared<SimCli>();
  CLI::App* cmd = sim->add_subcommand(
      "ros2",
      "The simulator as a ROS 2 robot: RGB-D, CameraInfo, /tf, /tf_static, /joint_states; obeys "
      "JointTrajectory goals (docs/ros2.md)");
  AddRunOptions(*cmd, cli->run);
  cmd->remove_option(cmd->get_option("--out"));
  cmd->remove_option(cmd->get_option("--force"));
  AddKeyValueOption(*cmd, "--sim-option", cli->sim_options,
                    "A key of the config's sim: section (repeatable), e.g. time_scale=0, "
                    "depth_encoding=16UC1, camera_rate_hz=30");
  cmd->add_option("--node-name", cli->node_name, "The ROS 2 node's name")
      ->default_str(cli->node_name);
  AddNumberOption(*cmd, "--domain-id", cli->domain_id, -1, 232,
                  "ROS_DOMAIN_ID (-1: the environment's, else 0)");
  cmd->add_option("--distro", cli->distro, "The peers' ROS 2 distribution: humble or jazzy")
      ->default_str(cli->distro);
  AddNumberOption(*cmd, "--duration", cli->duration_s, 0.0, 1e7,
                  "Stop after this many seconds (0: Ctrl-C)");
  cmd->callback([cli, cmd, &context] {
    RunGuarded(context, [&] { return SimRos2(*cmd, *cli, *context.registries); });
  });
}

}  // namespace avp::apps
