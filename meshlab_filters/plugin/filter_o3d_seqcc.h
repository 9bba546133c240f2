/* o3d_seqcc's MeshLab filter plugin: the two jobs of o3d_seqcc in MeshLab's Filters menu.
 *
 * Copyright (C) the o3d_seqcc authors. This file is part of the MeshLab plugin of o3d_seqcc, which links
 * MeshLab's GPL library (libmeshlab-common): it is free software under the GNU General Public License
 * version 3 (see LICENSE in this folder). The rest of o3d_seqcc is MIT-licensed.
 *
 * The filters' names, descriptions and parameters (with the library's defaults and help texts) are not
 * written here: they come from o3d_seqcc_filters.h, generated at build time by
 * `python -m meshlab_filters.native header` from the Python library (see meshlab_filters/native.py).
 */
#ifndef FILTER_O3D_SEQCC_H
#define FILTER_O3D_SEQCC_H

#include <QJsonArray>
#include <QJsonObject>
#include <QObject>
#include <QStringList>

#include "meshlab_api.h"

class FilterO3dSeqccPlugin : public QObject, public FilterBase
{
	Q_OBJECT
	MESHLAB_PLUGIN_IID_EXPORTER(O3D_SEQCC_FILTER_IID)
#ifdef O3D_SEQCC_MESHLAB_2022
	Q_INTERFACES(FilterPlugin)
#else
	Q_INTERFACES(MeshFilterInterface)
#endif

public:
	// order of the filters in o3d_seqcc_filters.h
	enum { FP_CORRECT = 0, FP_TEXTURE = 1 };

	FilterO3dSeqccPlugin();

	QString pluginName() const override;
	using FilterBase::filterName;
	using FilterBase::filterInfo;
	QString filterName(int filter) const override;
	QString filterInfo(int filter) const override;
	FilterClass getClass(FilterAction *a) O3D_SEQCC_CONST_GETTER override;
	int getPreConditions(FilterAction *a) const override;
	int postCondition(FilterAction *a) const override;
#ifdef O3D_SEQCC_MESHLAB_2022
	using FilterBase::pythonFilterName;
	QString pythonFilterName(int filter) const override;  // pymeshlab: the names meshlab_filters.apply takes
	FilterArity filterArity(const QAction *a) const override;
	RichParameterList initParameterList(const QAction *a, const MeshDocument &md) override;
	std::map<std::string, QVariant> applyFilter(const QAction *a, const RichParameterList &par, MeshDocument &md,
	                                            unsigned int &postConditionMask, vcg::CallBackPos *cb) override;
#else
	FILTER_ARITY filterArity(QAction *a) const override;
	using FilterBase::initParameterSet;
	void initParameterSet(QAction *a, MeshDocument &md, RichParameterList &par) override;
	bool applyFilter(QAction *a, MeshDocument &md, const RichParameterList &par, vcg::CallBackPos *cb) override;
#endif

	/// The o3d-seqcc executable the filters run: $O3D_SEQCC_EXECUTABLE, else the one this plugin was built
	/// with, else o3d-seqcc on PATH; empty if none (then *why says where it looked).
	static QString findExecutable(QString *why);

private:
	QJsonObject spec(int id) const;
	void parameters(int id, const MeshDocument &md, RichParameterList &par) const;
	bool run(int id, MeshDocument &md, const RichParameterList &par, vcg::CallBackPos *cb);
	QStringList childArguments(const QJsonObject &f, const RichParameterList &par, const QString &project,
	                           const QString &out, QString *command) const;
	QString outputFolder(const MeshDocument &md, const QString &given) const;
	QString meshLabWords(const QJsonObject &f, QString message) const;
	void say(GLLogStream::Levels level, const QString &text);
	bool fail(const QString &message);

	QJsonArray filters;
	QString failure;  // the last error message
};

#endif
