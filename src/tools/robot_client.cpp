// cellsight_robot_client: a robot controller's side of robot_bridge, for trying the bridge and as
// the simulated controller of the demo. Sends each command as one line, prints the answers.
//   cellsight_robot_client --port 30300 HELLO my_robot ADJUST "UCS weld_a" "INPOS 1"
// Exit 0 when every answer starts with OK, 3 when one is an ERR, 1 when the bridge cannot be
// reached or an answer does not come within --timeout.
#include <iostream>
#include <nlohmann/json.hpp>

#include "cellsight/bridge/line_client.hpp"
#include "cellsight/common/file_io.hpp"
#include "cli_args.hpp"

int main(int argc, char** argv) {
  std::string host = "127.0.0.1", json_out;
  int port = 30300;
  double timeout = 10.0;
  std::vector<std::string> commands;
  CLI::App app("A robot controller's side of robot_bridge: one line per command, the answers printed.",
               "cellsight_robot_client");
  app.add_option("--host", host, "bridge address (IPv4)")->capture_default_str();
  app.add_option("--port", port, "bridge port")->check(CLI::Range(1, 65535))->capture_default_str();
  app.add_option("--timeout", timeout, "seconds to wait for each answer")->check(cellsight_tools::positive())->capture_default_str();
  app.add_option("--json", json_out, "also write the session (requests and answers) here, atomically");
  app.add_option("commands", commands, "requests, e.g. HELLO me, ADJUST, \"UCS weld_a\", \"INPOS 1\", QUIT")->required();
  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  return cellsight_tools::runTool([&] {
    cellsight::LineClient client(host, port, timeout);
    nlohmann::json session = nlohmann::json::array();
    int rc = 0;
    for (const auto& c : commands) {
      if (!client.sendLine(c)) throw std::runtime_error("the bridge closed the connection before '" + c + "'");
      bool closed = false;
      const std::string answer = client.readLine(timeout, &closed);
      if (answer.empty()) {
        throw std::runtime_error(closed ? "the bridge closed the connection after '" + c + "'"
                                        : "no answer to '" + c + "' within " + std::to_string(timeout) + " s");
      }
      std::cout << "> " << c << "\n< " << answer << "\n";
      session.push_back({{"request", c}, {"answer", answer}});
      if (answer.rfind("OK", 0) != 0) rc = 3;
    }
    if (!json_out.empty()) cellsight::writeFileAtomic(json_out, session.dump(2) + "\n");
    return rc;
  });
}
