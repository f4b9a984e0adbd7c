#include "sonoshape/acquisition/plus_config.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <pugixml.hpp>
#include <sstream>

#include "sonoshape/acquisition/sequence_file.hpp"
#include "sonoshape/core/input_file.hpp"

namespace sonoshape::acquisition {

namespace {

// Two definitions of one transform that disagree: the configuration does not say which is
// right, so neither is taken (the first one silently was, before).
Status check_single_definition(const std::vector<PlusTransform>& transforms,
                               const std::string& from, const std::string& to) {
  const PlusTransform* first = nullptr;
  for (const PlusTransform& t : transforms) {
    const bool direct = t.from == from && t.to == to;
    const bool reverse = t.from == to && t.to == from;
    if (!direct && !reverse) continue;
    const Eigen::Matrix4d m = direct ? t.matrix : Eigen::Matrix4d(t.matrix.inverse());
    if (!first) {
      first = &t;
      continue;
    }
    const Eigen::Matrix4d f =
        first->from == from ? first->matrix : Eigen::Matrix4d(first->matrix.inverse());
    if ((m - f).cwiseAbs().maxCoeff() > 1e-9 * std::max(1.0, f.cwiseAbs().maxCoeff()))
      return Status::error("PLUS configuration defines " + from + "To" + to +
                           " twice with different matrices (<Transform From=\"" + first->from +
                           "\" To=\"" + first->to + "\"> and <Transform From=\"" + t.from +
                           "\" To=\"" + t.to +
                           "\">); keep the one that is right and delete the other");
  }
  return Status::ok();
}

}  // namespace

Result<Eigen::Matrix4d> PlusConfig::transform(const std::string& from,
                                              const std::string& to) const {
  if (Status single = check_single_definition(transforms, from, to); !single) return single;
  for (const PlusTransform& t : transforms)
    if (t.from == from && t.to == to) return t.matrix;
  for (const PlusTransform& t : transforms)
    if (t.from == to && t.to == from) {
      Eigen::Matrix4d inverse;
      bool invertible = false;
      t.matrix.computeInverseWithCheck(inverse, invertible);
      if (!invertible)
        return Status::error("PLUS configuration: " + to + "To" + from + " is singular, so " +
                             from + "To" + to + " cannot be derived");
      return inverse;
    }
  std::string known;
  for (const PlusTransform& t : transforms)
    known += (known.empty() ? "" : ", ") + t.from + "To" + t.to;
  return Status::error("PLUS configuration has no " + from + "To" + to +
                       " transform (it defines: " + (known.empty() ? "none" : known) +
                       "); add <Transform From=\"" + from + "\" To=\"" + to +
                       "\" Matrix=\"...\"/> to <CoordinateDefinitions>");
}

Result<PlusConfig> read_plus_config(const std::filesystem::path& path) {
  const std::string where = "PLUS configuration " + path.string();
  if (Status file = check_input_file(path, "PLUS configuration"); !file) return file;
  pugi::xml_document doc;
  const pugi::xml_parse_result parsed = doc.load_file(path.c_str());
  if (!parsed)
    return Status::error(where + ": " + parsed.description() + " at byte " +
                         std::to_string(parsed.offset) +
                         "; check that the file exists and is well-formed XML");
  // A device set keeps its transforms in <CoordinateDefinitions>; fCal's and the TRUS template
  // calibration's result file (*.results.xml) in <CalibrationResults>.
  pugi::xml_node transforms = doc.child("PlusConfiguration").child("CoordinateDefinitions");
  if (!doc.child("PlusConfiguration")) {
    transforms = doc.child("ProbeCalibrationResult").child("CalibrationResults");
    if (!transforms)
      return Status::error(where + ": the root element is <" +
                           std::string(doc.first_child().name()) +
                           ">, neither a PLUS device set (<PlusConfiguration> with "
                           "<CoordinateDefinitions>) nor a PLUS calibration result "
                           "(<ProbeCalibrationResult> with <CalibrationResults>); give one of "
                           "those");
  }
  PlusConfig config;
  int index = 0;
  for (const pugi::xml_node node : transforms.children("Transform")) {
    const std::string element = where + ": <Transform> #" + std::to_string(index++);
    PlusTransform t;
    t.from = node.attribute("From").as_string();
    t.to = node.attribute("To").as_string();
    if (t.from.empty() || t.to.empty())
      return Status::error(element + " needs both From and To attributes");
    // Result files spread the matrix over lines, tab-separated.
    std::string text = node.attribute("Matrix").as_string();
    std::replace_if(
        text.begin(), text.end(), [](char c) { return c == '\n' || c == '\r'; }, ' ');
    const auto matrix = parse_matrix(text);
    if (!matrix)
      return Status::error(element + " (" + t.from + "To" + t.to +
                           "): Matrix must be 16 numbers, a row-major 4x4");
    t.matrix = *matrix;
    if (const pugi::xml_attribute error = node.attribute("Error")) t.error = error.as_double();
    t.date = node.attribute("Date").as_string();
    config.transforms.push_back(std::move(t));
  }
  return config;
}

Result<Eigen::Matrix4d> read_image_to_probe(const std::filesystem::path& path) {
  auto config = read_plus_config(path);
  if (!config) return config.status();
  auto matrix = config->transform("Image", "Probe");
  if (!matrix) return Status::error(path.string() + ": " + matrix.message());
  return matrix;
}

Status write_plus_config(const PlusConfig& config, const std::filesystem::path& path,
                         const std::string& description) {
  pugi::xml_document doc;
  pugi::xml_node root = doc.append_child("PlusConfiguration");
  root.append_attribute("version") = "2.1";
  if (!description.empty())
    root.append_child(pugi::node_comment).set_value((" " + description + " ").c_str());
  pugi::xml_node defs = root.append_child("CoordinateDefinitions");
  for (const PlusTransform& t : config.transforms) {
    pugi::xml_node node = defs.append_child("Transform");
    node.append_attribute("From") = t.from.c_str();
    node.append_attribute("To") = t.to.c_str();
    node.append_attribute("Matrix") = format_matrix(t.matrix).c_str();
    if (t.error) node.append_attribute("Error") = *t.error;
    if (!t.date.empty()) node.append_attribute("Date") = t.date.c_str();
  }
  if (!doc.save_file(path.c_str(), "  "))
    return Status::error("cannot write PLUS configuration " + path.string() +
                         "; check that the directory exists and is writable");
  return Status::ok();
}

}  // namespace sonoshape::acquisition
