/* o3d_seqcc's MeshLab filter plugin (GPL-3, see LICENSE in this folder and filter_o3d_seqcc.h).
 *
 * Each filter writes the document as a MeshLab project into a temporary folder (the current mesh as a binary
 * PLY with its placement matrix applied, every raster with its camera and image file), runs
 * `o3d-seqcc -v COMMAND project.mlp --out DIR ... --progress-lines` as a child process, streams the child's
 * log into MeshLab's log and its progress lines into the progress bar, and then
 *   - "Sequential colour correction of rasters": replaces each raster's image by DIR/images/<raster>.png
 *     (read from DIR/scene.json, in raster order);
 *   - "Seamless texture from rasters": adds DIR/mesh_meshlab.ply (MeshLab's own textured PLY) as a new,
 *     current layer.
 * On failure the child's error message (o3d-seqcc's "error: ..." line, the CLI options named by their MeshLab
 * labels) becomes the filter's error message and a warning in the log.
 */
#include "filter_o3d_seqcc.h"
#include "o3d_seqcc_filters.h"  // generated: O3D_SEQCC_FILTERS_JSON

#include <QCoreApplication>
#include <QDir>
#include <QDomDocument>
#include <QElapsedTimer>
#include <QFile>
#include <QFileInfo>
#include <QJsonDocument>
#include <QProcess>
#include <QRegularExpression>
#include <QStandardPaths>
#include <QTemporaryDir>
#include <QTextStream>

#include <vcg/complex/append.h>
#include <vcg/complex/algorithms/update/position.h>
#include <wrap/io_trimesh/export_ply.h>
#include <wrap/io_trimesh/import_ply.h>

#ifndef O3D_SEQCC_EXECUTABLE
#define O3D_SEQCC_EXECUTABLE ""
#endif

using namespace vcg;

namespace {

const char *const PROGRESS_PREFIX = "o3d-seqcc-progress ";

/// meshlabserver prints the progress callback's text as it is: give it whole lines there
bool headless()
{
	return QFileInfo(QCoreApplication::applicationFilePath()).fileName().startsWith("meshlabserver");
}

QString num(double x)
{
	return QString::number(x, 'g', 9);  // 9 significant digits: every float round-trips
}

/// The raster's image file: absolute, or written from memory into dir when MeshLab has no file for it
QString rasterImageFile(const MeshDocument &md, RasterModel *r, int index, const QString &dir, QString *err)
{
	RasterImage *pl = r->currentPlane != nullptr ? r->currentPlane : (r->planeList.isEmpty() ? nullptr : r->planeList[0]);
	if (pl == nullptr) {
		*err = QString("raster %1 ('%2') has no image").arg(index).arg(r->label());
		return QString();
	}
	QFileInfo fi(pl->fullPathFileName);
	if (fi.isRelative())
		fi = QFileInfo(QDir(md.pathName()).absoluteFilePath(pl->fullPathFileName));
	if (fi.isFile())
		return fi.absoluteFilePath();
	if (!pl->image.isNull()) {
		QString path = QDir(dir).absoluteFilePath(QString("raster_%1.png").arg(index));
		if (pl->image.save(path, "PNG"))
			return path;
	}
	*err = QString("raster %1 ('%2'): its image %3 is not a readable file").arg(index).arg(r->label(),
	                                                                            pl->fullPathFileName);
	return QString();
}

/// A VCGCamera element as MeshLab writes it (text form), with every float's digits kept
QDomElement cameraElement(const Shotm &shot, QDomDocument &doc)
{
	QDomElement e = doc.createElement("VCGCamera");
	const Point3m t = -shot.Extrinsics.Tra();
	e.setAttribute("TranslationVector", QString("%1 %2 %3 1").arg(num(t[0]), num(t[1]), num(t[2])));
	const Matrix44m rot = shot.Extrinsics.Rot();
	QStringList r;
	for (int i = 0; i < 4; ++i)
		for (int j = 0; j < 4; ++j)
			r << num(rot[i][j]);
	e.setAttribute("RotationMatrix", r.join(' '));
	const Camera<Scalarm> &c = shot.Intrinsics;
	e.setAttribute("CameraType", c.cameraType);
	e.setAttribute("FocalMm", num(c.FocalMm));
	e.setAttribute("LensDistortion", QString("%1 %2").arg(num(c.k[0]), num(c.k[1])));
	e.setAttribute("PixelSizeMm", QString("%1 %2").arg(num(c.PixelSizeMm[0]), num(c.PixelSizeMm[1])));
	e.setAttribute("ViewportPx", QString("%1 %2").arg(c.ViewportPx[0]).arg(c.ViewportPx[1]));
	e.setAttribute("CenterPx", QString("%1 %2").arg(num(c.CenterPx[0]), num(c.CenterPx[1])));
	return e;
}

/// dir/project.mlp: the current mesh (dir/mesh.ply, placement applied) and every raster
QString exportProject(MeshDocument &md, MeshModel &mm, const QString &dir, vcg::CallBackPos *cb, QString *err)
{
	const QString meshPath = QDir(dir).absoluteFilePath("mesh.ply");
	CMeshO *src = &mm.cm;
	CMeshO placed;
	if (mm.cm.Tr != Matrix44m::Identity()) {  // o3d_seqcc works in world coordinates, as the rasters are
		tri::Append<CMeshO, CMeshO>::MeshCopy(placed, mm.cm, false, true);
		tri::UpdatePosition<CMeshO>::Matrix(placed, mm.cm.Tr, false);
		src = &placed;
	}
	int res = tri::io::ExporterPLY<CMeshO>::Save(*src, qUtf8Printable(meshPath), 0, true, cb);
	if (res != 0) {
		*err = QString("cannot write %1: %2").arg(meshPath, tri::io::ExporterPLY<CMeshO>::ErrorMsg(res));
		return QString();
	}
	QDomDocument doc("MeshLabDocument");
	QDomElement root = doc.createElement("MeshLabProject");
	doc.appendChild(root);
	QDomElement meshes = doc.createElement("MeshGroup");
	root.appendChild(meshes);
	QDomElement m = doc.createElement("MLMesh");
	m.setAttribute("label", mm.label());
	m.setAttribute("filename", "mesh.ply");
	m.setAttribute("visible", 1);
	QDomElement mat = doc.createElement("MLMatrix44");
	mat.appendChild(doc.createTextNode("\n1 0 0 0 \n0 1 0 0 \n0 0 1 0 \n0 0 0 1 \n"));
	m.appendChild(mat);
	meshes.appendChild(m);
	QDomElement rasters = doc.createElement("RasterGroup");
	root.appendChild(rasters);
	const std::vector<RasterModel *> all = mlapi::rasters(md);
	for (int i = 0; i < int(all.size()); ++i) {
		RasterModel *r = all[i];
		QString image = rasterImageFile(md, r, i, dir, err);
		if (image.isEmpty())
			return QString();
		QDomElement re = doc.createElement("MLRaster");
		re.setAttribute("label", r->label());
		re.appendChild(cameraElement(r->shot, doc));
		QDomElement pl = doc.createElement("Plane");
		pl.setAttribute("semantic", 1);
		pl.setAttribute("fileName", image);
		re.appendChild(pl);
		rasters.appendChild(re);
	}
	const QString project = QDir(dir).absoluteFilePath("project.mlp");
	QFile f(project);
	if (!f.open(QIODevice::WriteOnly | QIODevice::Truncate)) {
		*err = QString("cannot write %1: %2").arg(project, f.errorString());
		return QString();
	}
	QTextStream(&f) << doc.toString(1);
	return project;
}

QString shellQuoted(const QStringList &args)
{
	QStringList out;
	for (const QString &a : args)
		out << (a.contains(QRegularExpression("[^A-Za-z0-9_./=:,+-]")) ? "'" + QString(a).replace("'", "'\\''") + "'" : a);
	return out.join(' ');
}

}  // namespace

// ---------------------------------------------------------------------------------------------------------------

FilterO3dSeqccPlugin::FilterO3dSeqccPlugin()
{
	filters = QJsonDocument::fromJson(QByteArray(O3D_SEQCC_FILTERS_JSON)).array();
	typeList.push_back(FP_CORRECT);
	typeList.push_back(FP_TEXTURE);
	for (int tt : types())
		actionList.push_back(new QAction(filterName(tt), this));
}

QString FilterO3dSeqccPlugin::pluginName() const { return "FilterO3dSeqcc"; }

QJsonObject FilterO3dSeqccPlugin::spec(int id) const { return filters.at(id).toObject(); }

QString FilterO3dSeqccPlugin::filterName(int filter) const { return spec(filter)["title"].toString(); }

QString FilterO3dSeqccPlugin::filterInfo(int filter) const { return spec(filter)["info"].toString(); }

FilterO3dSeqccPlugin::FilterClass FilterO3dSeqccPlugin::getClass(FilterAction *a) O3D_SEQCC_CONST_GETTER
{
	// both under Filters > Texture; the correction also under Filters > Raster Layer
	return ID(a) == FP_CORRECT ? FilterClass(RasterLayer | Texture) : Texture;
}

int FilterO3dSeqccPlugin::getPreConditions(FilterAction *) const { return MeshModel::MM_FACENUMBER; }

int FilterO3dSeqccPlugin::postCondition(FilterAction *) const { return MeshModel::MM_NONE; }

#ifdef O3D_SEQCC_MESHLAB_2022
QString FilterO3dSeqccPlugin::pythonFilterName(int filter) const { return spec(filter)["python_name"].toString(); }

FilterO3dSeqccPlugin::FilterArity FilterO3dSeqccPlugin::filterArity(const QAction *) const { return SINGLE_MESH; }

RichParameterList FilterO3dSeqccPlugin::initParameterList(const QAction *a, const MeshDocument &md)
{
	RichParameterList par;
	parameters(ID(a), md, par);
	return par;
}

std::map<std::string, QVariant> FilterO3dSeqccPlugin::applyFilter(const QAction *a, const RichParameterList &par,
                                                                 MeshDocument &md, unsigned int &, vcg::CallBackPos *cb)
{
	if (!run(ID(a), md, par, cb))
		throw MLException(failure);
	return {};
}
#else
FilterO3dSeqccPlugin::FILTER_ARITY FilterO3dSeqccPlugin::filterArity(QAction *) const { return SINGLE_MESH; }

void FilterO3dSeqccPlugin::initParameterSet(QAction *a, MeshDocument &md, RichParameterList &par)
{
	parameters(ID(a), md, par);
}

bool FilterO3dSeqccPlugin::applyFilter(QAction *a, MeshDocument &md, const RichParameterList &par,
                                       vcg::CallBackPos *cb)
{
	errorMessage.clear();
	const bool ok = run(ID(a), md, par, cb);
	if (!ok)
		errorMessage = failure;
	return ok;
}
#endif

void FilterO3dSeqccPlugin::say(GLLogStream::Levels level, const QString &text)
{
#ifdef O3D_SEQCC_MESHLAB_2022
	log(level, qUtf8Printable(text));
#else
	Log(level, qUtf8Printable(text));
#endif
}

void FilterO3dSeqccPlugin::parameters(int id, const MeshDocument &md, RichParameterList &par) const
{
	for (const QJsonValue &v : spec(id)["parameters"].toArray()) {
		const QJsonObject p = v.toObject();
		const QString name = p["name"].toString(), kind = p["kind"].toString(), label = p["label"].toString();
		const QString tip = p["tooltip"].toString(), def = p["default"].toString();
		if (kind == "bool")
			par.addParam(RichBool(name, def == "true", label, tip));
		else if (kind == "int")
			par.addParam(RichInt(name, def.toInt(), label, tip));
		else if (kind == "float")
			par.addParam(RichFloat(name, def.toFloat(), label, tip));
		else if (kind == "enum" || kind == "raster") {
			QStringList values;
			if (kind == "raster") {  // "auto", then the document's rasters (index k + 1 = raster k)
				values << "auto";
				for (const QString &label : mlapi::rasterLabels(md))
					values << label;
			}
			else
				for (const QJsonValue &x : p["values"].toArray())
					values << x.toString();
			par.addParam(RichEnum(name, std::max(0, int(values.indexOf(def))), values, label, tip));
		}
		else
			par.addParam(RichString(name, def, label, tip));
	}
}

QString FilterO3dSeqccPlugin::findExecutable(QString *why)
{
	QStringList tried;
	const QString env = qEnvironmentVariable("O3D_SEQCC_EXECUTABLE");
	if (!env.isEmpty()) {
		if (QFileInfo(env).isExecutable())
			return env;
		tried << QString("$O3D_SEQCC_EXECUTABLE=%1 (not an executable)").arg(env);
	}
	const QString built(O3D_SEQCC_EXECUTABLE);
	if (!built.isEmpty()) {
		if (QFileInfo(built).isExecutable())
			return built;
		tried << QString("%1 (the one this plugin was built with: gone)").arg(built);
	}
	const QString onPath = QStandardPaths::findExecutable("o3d-seqcc");
	if (!onPath.isEmpty())
		return onPath;
	tried << "o3d-seqcc on PATH (none)";
	if (why)
		*why = "o3d-seqcc not found; looked for " + tried.join(", ") +
		       ". Install o3d_seqcc (./dev.sh setup in its checkout, or pip install CHECKOUT) and rebuild the "
		       "plugin, or set O3D_SEQCC_EXECUTABLE to its o3d-seqcc.";
	return QString();
}

QString FilterO3dSeqccPlugin::outputFolder(const MeshDocument &md, const QString &given) const
{
	QString path = given.trimmed();
	if (path.startsWith("~/"))
		path = QDir::home().absoluteFilePath(path.mid(2));
	if (QFileInfo(path).isAbsolute())
		return QDir::cleanPath(path);
	// relative: next to the project, else next to the current mesh's file, else in the home folder
	QFileInfo project(md.docLabel());
	QString base;
	if (project.isAbsolute() && project.isFile())
		base = project.absolutePath();
	else if (md.mm() != nullptr && !md.mm()->fullName().isEmpty())
		base = md.mm()->pathName();
	else
		base = QDir::homePath();
	return QDir::cleanPath(QDir(base).absoluteFilePath(path));
}

QStringList FilterO3dSeqccPlugin::childArguments(const QJsonObject &f, const RichParameterList &par,
                                                  const QString &project, const QString &out, QString *command) const
{
	// the same rule as meshlab_filters.native.cli_arguments
	*command = f["command"].toString();
	const QString sw = f["switch"].toString();
	if (!sw.isEmpty() && !par.getBool(sw))
		*command = f["command_off"].toString();
	QStringList args;
	args << "-v" << *command << project;
	for (const QJsonValue &v : f["parameters"].toArray()) {
		const QJsonObject p = v.toObject();
		const QString name = p["name"].toString(), kind = p["kind"].toString(), flag = p["flag"].toString();
		if (!p["commands"].toArray().contains(QJsonValue(*command)))
			continue;
		if (name == "savedir")
			args << flag << out;
		else if (kind == "bool") {
			if (par.getBool(name))
				args << flag;
		}
		else if (kind == "int")
			args << flag << QString::number(par.getInt(name));
		else if (kind == "float")
			args << flag << QString::number(double(par.getFloat(name)), 'g', 7);
		else if (kind == "raster") {
			const int k = par.getEnum(name);
			args << flag << (k <= 0 ? QString("auto") : QString::number(k - 1));  // raster index
		}
		else if (kind == "enum") {
			const QJsonArray values = p["values"].toArray();
			const int k = par.getEnum(name);
			args << flag << values.at(std::max(0, std::min(k, values.size() - 1))).toString();
		}
		else
			args << flag << par.getString(name);
	}
	args << "--progress-lines";
	return args;
}

QString FilterO3dSeqccPlugin::meshLabWords(const QJsonObject &f, QString message) const
{
	// the child's messages name command-line options (--t-npm) and library keywords (t_npm): name the dialog's
	// fields instead (keywords only when they cannot be plain words: with an underscore)
	for (const QJsonValue &v : f["parameters"].toArray()) {
		const QJsonObject p = v.toObject();
		const QString label = QString("'%1'").arg(p["label"].toString());
		const QString flag = p["flag"].toString(), keyword = p["keyword"].toString();
		if (!flag.isEmpty())
			message.replace(QRegularExpression(QRegularExpression::escape(flag) + "(?![-\\w])"), label);
		if (keyword.contains('_'))
			message.replace(QRegularExpression("\\b" + QRegularExpression::escape(keyword) + "\\b"), label);
	}
	return message;
}

bool FilterO3dSeqccPlugin::fail(const QString &message)
{
	failure = message;
	say(GLLogStream::WARNING, "o3d_seqcc: " + message);
	return false;
}

bool FilterO3dSeqccPlugin::run(int id, MeshDocument &md, const RichParameterList &par, vcg::CallBackPos *cb)
{
	failure.clear();
	const QJsonObject f = spec(id);
	MeshModel *mm = md.mm();
	if (mm == nullptr || mm->cm.fn == 0)
		return fail("the current layer has no faces: make a triangle mesh the current layer (the rasters are "
		            "projected onto it)");
	if (mlapi::rasterCount(md) == 0)
		return fail("the document has no rasters: the filter needs registered photos of the mesh (File > Import "
		            "Raster... and align them, or open a MeshLab project .mlp that has rasters, such as the "
		            "project.mlp o3d-seqcc writes)");
	QString why;
	const QString exe = findExecutable(&why);
	if (exe.isEmpty())
		return fail(why);
	const QString out = outputFolder(md, par.getString("savedir"));

	QTemporaryDir tmp(QDir::temp().absoluteFilePath("o3d_seqcc_meshlab_XXXXXX"));
	if (!tmp.isValid())
		return fail("cannot create a temporary folder in " + QDir::tempPath() + ": " + tmp.errorString());
	QString err;
	if (cb)
		cb(0, headless() ? "o3d_seqcc: exporting the mesh and the rasters\n" : "o3d_seqcc: exporting the mesh and the rasters");
	const QString project = exportProject(md, *mm, tmp.path(), nullptr, &err);
	if (project.isEmpty())
		return fail(err);

	QString command;
	const QStringList args = childArguments(f, par, project, out, &command);
	say(GLLogStream::FILTER, "o3d_seqcc: running " + shellQuoted(QStringList(exe) + args));

	QProcess proc;
	proc.setProcessChannelMode(QProcess::MergedChannels);
	QProcessEnvironment env = QProcessEnvironment::systemEnvironment();
	env.insert("PYTHONUNBUFFERED", "1");  // lines as they are written
	env.insert("MPLBACKEND", "Agg");
	proc.setProcessEnvironment(env);
	proc.setWorkingDirectory(tmp.path());
	proc.start(exe, args);
	if (!proc.waitForStarted(60000))
		return fail(QString("cannot start %1: %2").arg(exe, proc.errorString()));

	QStringList errors, tail;
	QElapsedTimer clock;
	clock.start();
	int percent = 0;
	auto handle = [&](QString line) {
		line = line.trimmed();
		if (line.isEmpty())
			return;
		if (line.startsWith(PROGRESS_PREFIX)) {
			const QString rest = line.mid(int(strlen(PROGRESS_PREFIX)));
			const int sp = rest.indexOf(' ');
			bool ok = false;
			const int p = rest.left(sp < 0 ? rest.size() : sp).toInt(&ok);
			if (ok && cb) {
				percent = std::max(percent, std::min(100, p));
				QString text = QString("o3d_seqcc %1: %2").arg(command, sp < 0 ? QString() : rest.mid(sp + 1));
				if (headless())
					text = QString("%1% %2\n").arg(percent).arg(text);
				cb(percent, qUtf8Printable(text));
			}
			return;
		}
		static const QRegularExpression errorLine("^o3d-seqcc(?: [\\w-]+)?: (?:error: )?(.*)$");
		const QRegularExpressionMatch m = errorLine.match(line);
		const bool isError = m.hasMatch() && (line.contains(": error: ") || line.endsWith(": interrupted"));
		if (isError)
			errors << m.captured(1);
		const bool warning = isError || line.startsWith("WARNING") || line.startsWith("ERROR") ||
		                     line.startsWith("Traceback");
		say(warning ? GLLogStream::WARNING : GLLogStream::FILTER, line);
		tail << line;
		if (tail.size() > 12)
			tail.removeFirst();
	};
	QByteArray pending;
	auto drain = [&]() {
		pending += proc.readAll();
		int nl;
		while ((nl = pending.indexOf('\n')) >= 0) {
			handle(QString::fromUtf8(pending.left(nl)));
			pending.remove(0, nl + 1);
		}
	};
	while (proc.state() != QProcess::NotRunning) {
		proc.waitForReadyRead(100);
		drain();
		// MeshLab runs filters on its GUI thread: keep the window drawn (no user input while the filter runs)
		QCoreApplication::processEvents(QEventLoop::ExcludeUserInputEvents, 50);
	}
	proc.waitForFinished(-1);
	drain();
	if (!pending.isEmpty())
		handle(QString::fromUtf8(pending));

	if (proc.exitStatus() != QProcess::NormalExit || proc.exitCode() != 0) {
		QString message;
		if (!errors.isEmpty())
			message = meshLabWords(f, errors.join("\n"));
		else if (proc.exitStatus() != QProcess::NormalExit)
			message = QString("o3d-seqcc %1 crashed (%2); its last lines:\n%3").arg(command, proc.errorString(),
			                                                                       tail.join("\n"));
		else
			message = QString("o3d-seqcc %1 failed (exit code %2); its last lines:\n%3").arg(command)
			              .arg(proc.exitCode()).arg(tail.join("\n"));
		return fail(message);
	}
	say(GLLogStream::FILTER, QString("o3d_seqcc: %1 finished in %2 s -> %3").arg(command)
	                             .arg(clock.elapsed() / 1000.0, 0, 'f', 1).arg(out));

	if (id == FP_CORRECT) {
		// DIR/scene.json lists the views in raster order with their corrected images (relative to it)
		QFile sj(QDir(out).absoluteFilePath("scene.json"));
		if (!sj.open(QIODevice::ReadOnly))
			return fail(QString("o3d-seqcc correct wrote no %1").arg(sj.fileName()));
		const QJsonArray views = QJsonDocument::fromJson(sj.readAll()).object()["views"].toArray();
		const std::vector<RasterModel *> all = mlapi::rasters(md);
		if (views.size() != int(all.size()))
			return fail(QString("%1 lists %2 views for %3 rasters").arg(sj.fileName()).arg(views.size())
			                .arg(all.size()));
		QList<RasterImage *> planes;
		for (int i = 0; i < views.size(); ++i) {
			const QString image = QDir(out).absoluteFilePath(views[i].toObject()["image"].toString());
			RasterImage *pl = new RasterImage(image, RasterImage::RGBA);
			if (pl->image.isNull()) {
				delete pl;
				qDeleteAll(planes);
				return fail(QString("cannot read the corrected image %1").arg(image));
			}
			planes << pl;
		}
		for (int i = 0; i < planes.size(); ++i) {
			RasterModel *r = all[i];
			qDeleteAll(r->planeList);
			r->planeList.clear();
			r->addPlane(planes[i]);
			say(GLLogStream::FILTER, QString("o3d_seqcc: raster %1 now shows %2").arg(r->label(), planes[i]->fullName()));
		}
		emit md.rasterSetChanged();
		return true;
	}

	// FP_TEXTURE: DIR/mesh_meshlab.ply becomes a new, current layer (its texture stays in DIR)
	const QString ply = QDir(out).absoluteFilePath("mesh_meshlab.ply");
	if (!QFileInfo(ply).isFile())
		return fail(QString("o3d-seqcc %1 wrote no %2").arg(command, ply));
	const QString label = QFileInfo(mm->label()).completeBaseName() + "_textured";
	int mask = 0;
	tri::io::ImporterPLY<CMeshO>::LoadMask(qUtf8Printable(ply), mask);
	const bool wasVisible = mlapi::visible(*mm);
	mlapi::setVisible(*mm, false);  // the textured copy covers the source mesh: hide it (before the views hear of it)
	MeshModel *nm = md.addNewMesh(ply, label, true);
	mlapi::enable(*nm, mask);
	int res = tri::io::ImporterPLY<CMeshO>::Open(nm->cm, qUtf8Printable(ply), mask, nullptr);
	if (tri::io::ImporterPLY<CMeshO>::ErrorCritical(res)) {
		const int back = mm->id();
		mlapi::deleteMesh(md, nm);
		mlapi::setVisible(*mm, wasVisible);
		md.setCurrentMesh(back);
		return fail(QString("cannot read %1: %2").arg(ply, tri::io::ImporterPLY<CMeshO>::ErrorMsg(res)));
	}
	for (std::string &t : nm->cm.textures)  // MeshLab resolves texture names against its working folder
		t = qUtf8Printable(QDir(out).absoluteFilePath(QString::fromStdString(t)));
#ifdef O3D_SEQCC_MESHLAB_2022
	nm->loadTextures();  // the mesh holds its textures' images since 2022
#endif
	tri::UpdateNormal<CMeshO>::PerFaceNormalized(nm->cm);
	if (!(mask & tri::io::Mask::IOM_VERTNORMAL))
		tri::UpdateNormal<CMeshO>::PerVertexAngleWeighted(nm->cm);
	tri::UpdateBounding<CMeshO>::Box(nm->cm);
	say(GLLogStream::FILTER, QString("o3d_seqcc: added layer '%1' (%2 faces, texture %3); layer '%4' hidden")
	                             .arg(nm->label()).arg(nm->cm.fn)
	                             .arg(nm->cm.textures.empty() ? QString("none") : QString::fromStdString(nm->cm.textures[0]))
	                             .arg(mm->label()));
	return true;
}

MESHLAB_PLUGIN_NAME_EXPORTER(FilterO3dSeqccPlugin)
