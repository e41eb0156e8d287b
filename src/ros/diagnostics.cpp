#include "cellsight_ros/diagnostics.hpp"

#include <diagnostic_msgs/DiagnosticStatus.h>

#include <cstdio>

namespace cellsight_ros {

NodeDiagnostics::NodeDiagnostics(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& name,
                                 const std::string& what, double period)
    : updater_(nh, pnh), what_(what) {
  updater_.setHardwareID("cellsight");
  updater_.add(name, this, &NodeDiagnostics::produce);
  // force_update: update() waits a full period after the last publication and, with timer jitter,
  // skips every other tick
  timer_ = nh.createTimer(ros::Duration(period), [this](const ros::TimerEvent&) { updater_.force_update(); });
}

void NodeDiagnostics::processed(double seconds) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++processed_;
  last_seconds_ = seconds;
  if (seconds > max_seconds_) max_seconds_ = seconds;
}

namespace {

// A reason or value may carry a client's text (an object name): bounded in length and in number,
// so a client sending ever new names cannot grow the node or /diagnostics.
constexpr size_t kMaxText = 200, kMaxKeys = 32;
std::string bounded(const std::string& text) { return text.size() <= kMaxText ? text : text.substr(0, kMaxText) + "..."; }

}  // namespace

void NodeDiagnostics::dropped(const std::string& reason) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++dropped_;
  const std::string key = bounded(reason);
  if (reasons_.count(key) || reasons_.size() < kMaxKeys) ++reasons_[key];
  else ++reasons_["(other reasons)"];
}

void NodeDiagnostics::set(const std::string& key, const std::string& value) {
  std::lock_guard<std::mutex> lock(mutex_);
  const std::string k = bounded(key);
  if (values_.count(k) || values_.size() < kMaxKeys) values_[k] = bounded(value);
}

void NodeDiagnostics::addValue(const std::string& key, std::function<std::string()> fn) {
  std::lock_guard<std::mutex> lock(mutex_);
  computed_.emplace_back(key, std::move(fn));
}

void NodeDiagnostics::produce(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  std::lock_guard<std::mutex> lock(mutex_);
  const ros::WallTime now = ros::WallTime::now();
  const double dt = std::max(1e-6, (now - last_publication_).toSec());
  const uint64_t new_processed = processed_ - processed_at_last_;
  const uint64_t new_dropped = dropped_ - dropped_at_last_;
  char rate[32];
  std::snprintf(rate, sizeof(rate), "%.2f", static_cast<double>(new_processed) / dt);
  char last[32], worst[32];
  std::snprintf(last, sizeof(last), "%.4f", last_seconds_);
  std::snprintf(worst, sizeof(worst), "%.4f", max_seconds_);
  if (new_dropped > 0 && processed_ == 0) {
    stat.summaryf(diagnostic_msgs::DiagnosticStatus::ERROR, "every %s dropped (%lu)", what_.c_str(),
                  static_cast<unsigned long>(dropped_));
  } else if (new_dropped > 0) {
    stat.summaryf(diagnostic_msgs::DiagnosticStatus::WARN, "%lu %s dropped in the last %.1f s",
                  static_cast<unsigned long>(new_dropped), what_.c_str(), dt);
  } else {
    stat.summaryf(diagnostic_msgs::DiagnosticStatus::OK, "%lu %s processed", static_cast<unsigned long>(processed_),
                  what_.c_str());
  }
  stat.add(what_ + " processed", processed_);
  stat.add(what_ + " dropped", dropped_);
  stat.add(what_ + " per second", rate);
  stat.add("last processing time [s]", last);
  stat.add("longest processing time [s]", worst);
  for (const auto& [reason, n] : reasons_) stat.add("dropped: " + reason, n);
  for (const auto& [k, v] : values_) stat.add(k, v);
  for (const auto& [k, fn] : computed_) stat.add(k, fn());
  processed_at_last_ = processed_;
  dropped_at_last_ = dropped_;
  last_publication_ = now;
}

}  // namespace cellsight_ros
