// The sensors component: an emulated lidar (40 Hz) and odometry (100 Hz),
// stamped with the time the sensor took them. They see the robot's true
// state, which the driver publishes.
#include <cstdio>
#include <memory>
#include <random>

#include "components.hpp"
#include "messages.hpp"

namespace robot {

using namespace std::chrono_literals;

prime::system::Component sensors() {
  return prime::system::Component{"robot.sensors"}
      .publishes<Scan>("sensors/lidar", {.capacity = 16})
      .publishes<Odometry>("sensors/odom", {.capacity = 32})
      .subscribes<State>("driver/state", {.capacity = 8})
      .every("sample", 10ms)
      .build([](prime::system::Context& ctx) {
        struct Sensing {
          prime::Reader<State> world;
          State state{1, 1, 0, 0, 0};
          std::mt19937 noise{7};
          std::normal_distribution<float> jitter{0, 0.01f};
          std::uint64_t ticks = 0, scans = 0, odoms = 0;
          prime::Clock::time_point last_print = prime::Clock::now();
        };
        auto s = std::make_shared<Sensing>(Sensing{ctx.input<State>("driver/state").subscribe()});
        ctx.every("sample", [s, lidar = ctx.output<Scan>("sensors/lidar"), odom = ctx.output<Odometry>("sensors/odom")](prime::Token) {
          if (auto w = s->world.latest()) s->state = w->value;
          const auto now = prime::Clock::now();
          const auto& st = s->state;
          if (odom.publish(Odometry{st.x, st.y, st.heading}, now)) ++s->odoms;  // 100 Hz
          const auto t = s->ticks++ % 10;
          if (t == 0 || t == 3 || t == 5 || t == 8) {  // 40 Hz
            const Scan scan{{static_cast<float>(kRoom - st.x) + s->jitter(s->noise), static_cast<float>(kRoom - st.y) + s->jitter(s->noise),
                             static_cast<float>(st.x) + s->jitter(s->noise), static_cast<float>(st.y) + s->jitter(s->noise)}};
            if (lidar.publish(scan, now)) ++s->scans;
          }
          if (now - s->last_print >= 1s) {
            std::printf("[sensors] lidar %llu Hz, odometry %llu Hz\n", static_cast<unsigned long long>(s->scans),
                        static_cast<unsigned long long>(s->odoms));
            std::fflush(stdout);
            s->scans = s->odoms = 0;
            s->last_print = now;
          }
        });
      });
}

}  // namespace robot

PRIME_COMPONENT(robot::sensors());
