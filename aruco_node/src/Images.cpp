#include <cpm/aruco/Images.hpp>

#include <cpm/Error.hpp>

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cctype>
#include <filesystem>

namespace cpm::aruco {

void write_image(const std::string& path, const cv::Mat& image)
{
    bool ok = false;
    try {
        ok = cv::imwrite(path, image);
    } catch (const cv::Exception& e) {
        throw Error(path + ": cannot write the image (" + e.err + ")");
    }
    if (!ok) throw Error(path + ": cannot write the image");
}

cv::Mat read_camera_image(const std::string& path, const Camera& camera)
{
    cv::Mat image = cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (image.empty()) throw Error(path + ": cannot read the image");
    if (image.cols != camera.width || image.rows != camera.height) {
        throw Error(path + ": " + std::to_string(image.cols) + "×" + std::to_string(image.rows) + " px, but the camera file says " +
                    std::to_string(camera.width) + "×" + std::to_string(camera.height));
    }
    return image;
}

std::vector<std::string> list_images(const std::string& folder)
{
    std::error_code ec;
    if (!std::filesystem::is_directory(folder, ec)) throw Error(folder + ": not a folder of images");
    std::vector<std::string> files;
    for (const auto& entry : std::filesystem::directory_iterator(folder, ec)) {
        std::string ext = entry.path().extension().string();
        std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
        for (const char* known : {".png", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm", ".tif", ".tiff"}) {
            if (ext == known) files.push_back(entry.path().string());
        }
    }
    if (ec) throw Error(folder + ": cannot list the folder (" + ec.message() + ")");
    if (files.empty()) throw Error(folder + ": no images (.png, .jpg, .bmp, .pgm, .ppm, .tif) in the folder");
    std::sort(files.begin(), files.end());
    return files;
}

}  // namespace cpm::aruco
