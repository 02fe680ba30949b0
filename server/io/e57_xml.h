/* e57_xml.h — the XML section of an E57 file as a tree of elements, parsed with expat.
 *
 * E57's XML is small (a few KiB per scan): every element keeps its local name, its namespace
 * class, its `type` attribute, its other attributes and its character data. Namespaces are
 * resolved: an element of the E57 namespace (or of none) is E57_NS_E57, one of the surface
 * normals extension (namespace URI http://www.libe57.org/E57_NOR_surface_normals.txt, or any
 * URI bound to the prefix "nor") E57_NS_NOR, any other extension E57_NS_OTHER (never taken for
 * an E57 element of the same local name). A document type declaration is refused (E57 has none;
 * it is how entity expansion attacks start).
 *
 * Limits: depth E57_XML_MAX_DEPTH, at most E57_XML_MAX_NODES elements; past them the parse
 * fails with a message. Everything lives in one arena freed by e57_xml_free. */
#pragma once
#include <stddef.h>
#include <stdint.h>

#include "sd_err.h"

enum { E57_NS_E57 = 0, E57_NS_NOR, E57_NS_OTHER };
enum { E57_XML_MAX_DEPTH = 64, E57_XML_MAX_NODES = 1 << 22 };

typedef struct e57_node {
    const char *name;          /* local name */
    int ns;                    /* E57_NS_* */
    const char *type;          /* the `type` attribute; "" when absent */
    const char *text;          /* character data (CDATA included); "" when none */
    const char *const *attrs;  /* the other attributes: name, value, ..., NULL */
    unsigned long line;        /* where the start tag is */
    struct e57_node *parent, *child, *next; /* first child, next sibling */
} e57_node;

typedef struct e57_xml e57_xml;

/* e57_xml_new: a parser. NULL when out of memory. */
e57_xml *e57_xml_new(void);
/* e57_xml_feed: the next n bytes of the document (final: they are the last). what names the
 * section in messages ("f.e57: the XML section at physical offset 1234"). Returns 0, or
 * SD_EFORMAT naming the line and column, SD_ELIMIT, SD_ENOMEM. */
int e57_xml_feed(e57_xml *x, const char *p, size_t n, int final, const char *what, sd_err *err);
/* e57_xml_root: the document element once the last bytes were fed; NULL before or on error. */
const e57_node *e57_xml_root(const e57_xml *x);
void e57_xml_free(e57_xml *x);

/* e57_child: the first child of n in the E57 namespace named name; NULL when none. */
const e57_node *e57_child(const e57_node *n, const char *name);
/* e57_attr: the value of n's attribute name; NULL when absent. */
const char *e57_attr(const e57_node *n, const char *name);
