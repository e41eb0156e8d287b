// Shared CLI11 helpers of the command-line tools: number validators with readable messages
// ("--square: '25mm' is not a number") and a validator backed by a library parser.
// Parse errors go through CLI11 (parse(): message on stderr, CLI11's non-zero exit code; --help
// exits 0); errors at run time are printed as "error: ..." with exit 1 by runTool().
#pragma once
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <exception>
#include <functional>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

namespace cellsight_tools {

namespace detail {

/// A number check: `ok` on the parsed value, `rule` (e.g. "> 0") in the message and the help.
inline CLI::Validator numberCheck(bool integer, std::function<bool(double)> ok, const std::string& rule,
                                  const std::string& desc) {
  return CLI::Validator(
      [integer, ok, rule](std::string& s) -> std::string {
        const char* b = s.c_str();
        char* e = nullptr;
        errno = 0;
        double v = 0;
        if (integer) {
          const long l = std::strtol(b, &e, 10);
          v = static_cast<double>(l);
        } else {
          v = std::strtod(b, &e);
        }
        if (s.empty() || e == b || *e != '\0' || errno == ERANGE || !std::isfinite(v))
          return "'" + s + "' is not " + (integer ? "an integer" : "a number");
        if (!ok(v)) return s + " is not " + rule;
        return std::string();
      },
      desc);
}

}  // namespace detail

/// A number > 0.
inline CLI::Validator positive() {
  return detail::numberCheck(false, [](double v) { return v > 0; }, "> 0", "POSITIVE");
}
/// A number >= 0.
inline CLI::Validator nonNegative() {
  return detail::numberCheck(false, [](double v) { return v >= 0; }, ">= 0", "NONNEGATIVE");
}
/// A number in [0, 1].
inline CLI::Validator fraction() {
  return detail::numberCheck(false, [](double v) { return v >= 0 && v <= 1; }, "in [0, 1]", "IN [0,1]");
}
/// An integer > 0.
inline CLI::Validator positiveInt() {
  return detail::numberCheck(true, [](double v) { return v > 0; }, "> 0", "POSITIVE");
}
/// An integer >= 0.
inline CLI::Validator nonNegativeInt() {
  return detail::numberCheck(true, [](double v) { return v >= 0; }, ">= 0", "NONNEGATIVE");
}

/// Accepts what `parse` accepts (it throws with a message otherwise), e.g. a library's
/// enum parser, so the tool and the library agree on the names.
inline CLI::Validator parsedBy(std::function<void(const std::string&)> parse, const std::string& desc) {
  return CLI::Validator(
      [parse](std::string& s) -> std::string {
        try {
          parse(s);
        } catch (const std::exception& e) {
          return e.what();
        }
        return std::string();
      },
      desc);
}

/// CLI11_PARSE as a function: the exit code when the tool must stop (--help: 0; a parse error:
/// CLI11's message and code), nothing when it should run. A first word that names no
/// subcommand is reported as such (CLI11 alone would say "A subcommand is required").
inline std::optional<int> parse(CLI::App& app, int argc, char** argv) {
  try {
    const auto subs = app.get_subcommands([](const CLI::App*) { return true; });
    if (!subs.empty() && argc > 1 && argv[1][0] != '-') {
      std::string names;
      bool known = false;
      for (const CLI::App* s : subs) {
        known = known || s->check_name(argv[1]);
        names += (names.empty() ? "" : ", ") + s->get_name();
      }
      if (!known)
        throw CLI::ExtrasError("unknown subcommand '" + std::string(argv[1]) + "' (one of: " + names + ")",
                               CLI::ExitCodes::ExtrasError);
    }
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // An unknown or misspelt option is the error to name, even when CLI11 first found a
    // required option missing (it checks requirements before leftovers).
    if (e.get_exit_code() != 0) {
      std::vector<std::string> unknown;
      for (const std::string& r : app.remaining(true))
        if (r.size() > 1 && r[0] == '-') unknown.push_back(r);
      for (const CLI::App* sub : app.get_subcommands())
        for (const std::string& r : sub->remaining(true))
          if (r.size() > 1 && r[0] == '-' && std::find(unknown.begin(), unknown.end(), r) == unknown.end())
            unknown.push_back(r);
      if (!unknown.empty()) {
        std::string list;
        for (const auto& u : unknown) list += (list.empty() ? "" : ", ") + u;
        return app.exit(CLI::ExtrasError("unknown option" + std::string(unknown.size() > 1 ? "s" : "") + ": " + list,
                                         CLI::ExitCodes::ExtrasError));
      }
    }
    return app.exit(e);
  }
  return std::nullopt;
}

/// Runs a tool's work after parsing: exceptions become "error: ..." and exit code 1.
inline int runTool(const std::function<int()>& body) {
  try {
    return body();
  } catch (const std::exception& e) {
    std::cerr << "error: " << e.what() << "\n";
    return 1;
  }
}

}  // namespace cellsight_tools
