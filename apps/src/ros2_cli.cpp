#include "ros2_cli.h"

namespace avp::apps {

namespace {
std::atomic<bool> g_interrupted{false};
extern "C" void OnInterrupt(int) { g_interrupted.store(true); }
}  // namespace

StopOnSignal::StopOnSignal(std::stop_source& stop, double timeout_s, std::string message,
                           std::function<void()> tick) {
  g_interrupted.store(false);
  old_int_ = std::signal(SIGINT, OnInterrupt);
  old_term_ = std::signal(SIGTERM, OnInterrupt);
  watcher_ = std::jthread([&stop, timeout_s, message = std::move(message),
                           tick = std::move(tick)](std::stop_token done) {
    const auto t0 = std::chrono::steady_clock::now();
    while (!done.stop_requested()) {
      if (tick) tick();
      if (g_interrupted.load()) {
        std::fprintf(stderr, "\n%s\n", message.c_str());
        stop.request_stop();
        return;
      }
      if (timeout_s > 0 &&
          std::chrono::steady_clock::now() - t0 > std::chrono::duration<double>(timeout_s)) {
        std::fprintf(stderr, "the time limit (%.0f s) is reached: stopping\n", timeout_s);
        stop.request_stop();
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  });
}

StopOnSignal::~StopOnSignal() {
  watcher_ = {};
  std::signal(SIGINT, old_int_);
  std::signal(SIGTERM, old_term_);
}

}  // namespace avp::apps
