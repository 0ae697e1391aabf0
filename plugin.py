"""The plugin object: registers the Processing provider (desktop and qgis_process) and, in the
desktop, offers to install missing Python packages into QGIS's own Python."""
from qgis.core import QgsApplication

from .provider.provider import GroundSieveProvider

LOG_TAG = "GroundSieve"


class GroundSievePlugin:
    def __init__(self, iface):
        self.iface = iface  # None under qgis_process
        self.provider = None
        self.message = None  # the message bar item about missing packages
        self.task = None     # the running install, if any

    def initProcessing(self):  # noqa: N802 (QGIS API name)
        if self.provider is None:
            provider = GroundSieveProvider()
            # A refused provider (e.g. the id already registered) is deleted by the registry.
            if QgsApplication.processingRegistry().addProvider(provider):
                self.provider = provider

    def initGui(self):  # noqa: N802 (QGIS API name)
        self.initProcessing()
        if self.iface is not None:
            self.check_dependencies()

    # -- missing packages ------------------------------------------------------------------------

    def missing(self):
        from .dependencies import TRAINING, missing_dependencies
        return missing_dependencies(TRAINING)

    def check_dependencies(self):
        """Say what is missing where it stays: a message bar item with an Install button (no
        timeout) and the full text, with the exact pip command, in the log."""
        from qgis.core import Qgis, QgsMessageLog
        from qgis.PyQt.QtWidgets import QPushButton

        from .dependencies import NOT_PIP, command_text, install_command
        missing = self.missing()
        if not missing:
            return []
        pip_names = [m for m in missing if m not in NOT_PIP]
        text = f"needs the Python packages {', '.join(missing)}."
        detail = ("The GroundSieve algorithms that need them stop with a message until they are installed "
                  "into QGIS's Python.")
        try:
            command = command_text(install_command(pip_names))
        except RuntimeError as err:
            command = str(err)
        QgsMessageLog.logMessage(f"GroundSieve {text} {detail} Install command: {command}", LOG_TAG, Qgis.Warning)
        bar = self.iface.messageBar()
        item = bar.createMessage("GroundSieve", text)
        if pip_names:
            button = QPushButton("Install…")
            button.clicked.connect(lambda: self.ask_and_install(pip_names))
            item.layout().addWidget(button)
        self.message = bar.pushWidget(item, Qgis.Warning, 0)
        return missing

    def ask_and_install(self, packages, confirm=None):
        """Show the exact command, ask, then run pip in a background task."""
        from qgis.PyQt.QtWidgets import QMessageBox

        from .dependencies import command_text, install_command
        command = command_text(install_command(packages))
        question = (f"GroundSieve will install {', '.join(packages)} into QGIS's Python for this user "
                    f"with pip, keeping numpy and scipy at the versions QGIS runs with:\n\n{command}\n\n"
                    "This downloads the packages from the Python Package Index. Go ahead?")
        if confirm is None:
            window = self.iface.mainWindow() if self.iface is not None else None
            answer = QMessageBox.question(window, "GroundSieve: install Python packages", question)
            confirm = answer == QMessageBox.Yes
        if not confirm:
            return None
        self.task = InstallTask(packages, self.installed)
        QgsApplication.taskManager().addTask(self.task)
        return self.task

    def installed(self, ok, output):
        """After pip: say what happened, in the bar and the log; clear the warning when done."""
        from qgis.core import Qgis, QgsMessageLog
        QgsMessageLog.logMessage(output[-4000:] or "(pip printed nothing)", LOG_TAG,
                                 Qgis.Info if ok else Qgis.Critical)
        still = self.missing()
        if self.iface is None:
            return still
        bar = self.iface.messageBar()
        if self.message is not None:
            bar.popWidget(self.message)
            self.message = None
        if ok and not still:
            bar.pushMessage("GroundSieve", "Python packages installed; the algorithms are ready.",
                            level=Qgis.Success, duration=10)
        else:
            bar.pushMessage("GroundSieve", "Installing the Python packages failed"
                            + (f" (still missing: {', '.join(still)})" if still else "")
                            + ": see Log Messages > GroundSieve for pip's output.", level=Qgis.Critical, duration=0)
        return still

    def unload(self):
        if self.provider is not None:
            QgsApplication.processingRegistry().removeProvider(self.provider)
            self.provider = None
        if self.message is not None and self.iface is not None:
            self.iface.messageBar().popWidget(self.message)
            self.message = None


class InstallTask:
    """pip in a QgsTask (off the GUI thread); ``done(ok, output)`` is called on the GUI thread."""

    def __new__(cls, packages, done):
        from qgis.core import QgsTask

        from .dependencies import install

        class _Task(QgsTask):
            def __init__(self):
                super().__init__("GroundSieve: installing Python packages", QgsTask.CanCancel)
                self.ok, self.output = False, ""

            def run(self):
                self.ok, self.output = install(packages, log=lambda _msg: None)
                return self.ok

            def finished(self, _result):
                done(self.ok, self.output)

        return _Task()
