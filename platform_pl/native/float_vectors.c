/*  Element-wise maths on packed float vectors, for float_vectors.pl.

    A packed vector is fts(String): String is what fast_term_serialized/2
    makes of a list of N floats, its code points the bytes

        114, varint(10N+1), varint(6N), N x [8, 14, <float64 LE>], 9

    ([122, 9] for the empty list; a varint is big-endian base 128 with
    the high bit set on every byte but the last). Every predicate here
    checks each vector completely (header, every element's tag, trailer,
    length) before it reads a value, and fails, rather than raising, on
    anything it does not take: a malformed or non-float vector, vectors
    of different lengths, a result that is not finite (where is/2 would
    raise a float overflow). float_vectors.pl then does the same work on
    lists, in Prolog, which raises what is/2 raises. The arithmetic is
    that of is/2 on floats (an integer weight or count is converted to a
    double first), so both paths give the same bits.
*/
#include <SWI-Prolog.h>
#include <stdlib.h>
#include <string.h>
#include <stdint.h>
#include <math.h>

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "float_vectors.c assumes a little-endian host (fts stores float64 little-endian)"
#endif

typedef struct
{ const unsigned char *elems;		/* first element's tag */
  size_t n;
} vec;

static functor_t FUNCTOR_fts1;

static int
read_varint(const unsigned char *b, size_t len, size_t *pos, uint64_t *v)
{ uint64_t x = 0;
  int i;

  for(i = 0; i < 10 && *pos < len; i++)
  { unsigned char c = b[(*pos)++];
    x = (x << 7) | (c & 0x7f);
    if ( !(c & 0x80) )
    { *v = x;
      return TRUE;
    }
  }
  return FALSE;
}

static size_t
varint_size(uint64_t v)
{ size_t n = 1;
  while ( v >>= 7 )
    n++;
  return n;
}

static unsigned char *
put_varint(unsigned char *p, uint64_t v)
{ size_t n = varint_size(v);
  size_t i;

  for(i = n; i-- > 0; )
  { unsigned char c = (unsigned char)((v >> (7*i)) & 0x7f);
    *p++ = (i > 0) ? (c | 0x80) : c;
  }
  return p;
}

/* t is fts(String) holding a well-formed float vector */
static int
get_vec(term_t t, vec *v)
{ term_t a;
  size_t len, pos = 0, i;
  char *s;
  const unsigned char *b;
  uint64_t v1, v2;

  if ( !PL_is_functor(t, FUNCTOR_fts1) )
    return FALSE;
  a = PL_new_term_ref();
  /* PL_get_string() points into the string itself (a string of code
     points below 256 is one byte a code point); PL_get_nchars() would
     copy it into a buffer first, most of the cost at 20,000 floats. */
  if ( !PL_get_arg(1, t, a) || !PL_get_string(a, &s, &len) )
    return FALSE;
  b = (const unsigned char *)s;
  if ( len == 2 && b[0] == 122 && b[1] == 9 )
  { v->elems = b;
    v->n = 0;
    return TRUE;
  }
  if ( len < 1 || b[pos++] != 114 )
    return FALSE;
  if ( !read_varint(b, len, &pos, &v1) || !read_varint(b, len, &pos, &v2) )
    return FALSE;
  if ( v2 == 0 || v2 % 6 != 0 )
    return FALSE;
  if ( v2 / 6 > len / 10 )		/* also keeps 10*n below from wrapping */
    return FALSE;
  v->n = (size_t)(v2 / 6);
  if ( v1 != 10*(uint64_t)v->n + 1 || len - pos != 10*v->n + 1 || b[len-1] != 9 )
    return FALSE;
  v->elems = b + pos;
  for(i = 0; i < v->n; i++)
  { if ( v->elems[10*i] != 8 || v->elems[10*i+1] != 14 )
      return FALSE;
  }
  return TRUE;
}

static inline double
elem(const vec *v, size_t i)
{ double d;
  memcpy(&d, v->elems + 10*i + 2, sizeof(d));
  return d;
}

/* A result vector of n floats, filled by the caller through *data */
typedef struct
{ unsigned char *buf;
  unsigned char *elems;
  size_t len;
  size_t n;
} out_vec;

static int
new_out(out_vec *o, size_t n)
{ size_t hdr = 1 + varint_size(10*(uint64_t)n + 1) + varint_size(6*(uint64_t)n);
  unsigned char *p;

  o->n = n;
  o->len = (n == 0) ? 2 : hdr + 10*n + 1;
  if ( !(o->buf = malloc(o->len)) )
    return PL_resource_error("memory");
  if ( n == 0 )
  { o->buf[0] = 122;
    o->buf[1] = 9;
    o->elems = o->buf;
    return TRUE;
  }
  p = o->buf;
  *p++ = 114;
  p = put_varint(p, 10*(uint64_t)n + 1);
  p = put_varint(p, 6*(uint64_t)n);
  o->elems = p;
  o->buf[o->len-1] = 9;
  return TRUE;
}

static inline void
set_elem(out_vec *o, size_t i, double d)
{ unsigned char *p = o->elems + 10*i;
  p[0] = 8;
  p[1] = 14;
  memcpy(p+2, &d, sizeof(d));
}

static int
unify_out(term_t t, out_vec *o)
{ term_t s = PL_new_term_ref();
  int rc = ( PL_put_chars(s, PL_STRING|REP_ISO_LATIN_1, o->len, (const char *)o->buf) &&
	     PL_unify_term(t, PL_FUNCTOR, FUNCTOR_fts1, PL_TERM, s) );
  free(o->buf);
  return rc;
}

static int
get_number(term_t t, double *d)
{ int64_t i;

  if ( PL_is_float(t) )
    return PL_get_float(t, d);
  if ( PL_is_integer(t) && PL_get_int64(t, &i) &&
       i >= -(1LL<<53) && i <= (1LL<<53) )
  { *d = (double)i;			/* exact, as is/2 converts it */
    return TRUE;
  }
  return FALSE;
}

typedef enum { OP_ADD, OP_MUL, OP_MAX } binop;

static foreign_t
fts_vector_length(term_t v, term_t n)
{ vec a;

  if ( !get_vec(v, &a) )
    return FALSE;
  return PL_unify_uint64(n, a.n);
}

static foreign_t
fts_vector_binop(term_t op, term_t x, term_t y, term_t z)
{ vec a, b;
  out_vec o;
  char *name;
  binop k;
  size_t i;

  if ( !PL_get_atom_chars(op, &name) )
    return FALSE;
  if ( strcmp(name, "add") == 0 ) k = OP_ADD;
  else if ( strcmp(name, "mul") == 0 ) k = OP_MUL;
  else if ( strcmp(name, "max") == 0 ) k = OP_MAX;
  else return FALSE;
  if ( !get_vec(x, &a) || !get_vec(y, &b) || a.n != b.n )
    return FALSE;
  if ( !new_out(&o, a.n) )
    return FALSE;
  for(i = 0; i < a.n; i++)
  { double p = elem(&a, i), q = elem(&b, i), r;

    switch(k)
    { case OP_ADD: r = p + q; break;
      case OP_MUL: r = p * q; break;
      default:     r = (p < q) ? q : p; break;	/* is/2's max/2 */
    }
    if ( !isfinite(r) )
    { free(o.buf);
      return FALSE;
    }
    set_elem(&o, i, r);
  }
  return unify_out(z, &o);
}

/* divide: each element / K;  times: K * each element */
static foreign_t
fts_vector_scale(term_t op, term_t x, term_t kt, term_t z)
{ vec a;
  out_vec o;
  char *name;
  double k;
  int divide;
  size_t i;

  if ( !PL_get_atom_chars(op, &name) )
    return FALSE;
  if ( strcmp(name, "divide") == 0 ) divide = TRUE;
  else if ( strcmp(name, "times") == 0 ) divide = FALSE;
  else return FALSE;
  if ( !get_number(kt, &k) || !get_vec(x, &a) )
    return FALSE;
  if ( divide && k == 0.0 )
    return FALSE;
  if ( !new_out(&o, a.n) )
    return FALSE;
  for(i = 0; i < a.n; i++)
  { double r = divide ? elem(&a, i) / k : k * elem(&a, i);

    if ( !isfinite(r) )
    { free(o.buf);
      return FALSE;
    }
    set_elem(&o, i, r);
  }
  return unify_out(z, &o);
}

/* Zs = Xs + W*Ys */
static foreign_t
fts_vector_add_scaled(term_t x, term_t wt, term_t y, term_t z)
{ vec a, b;
  out_vec o;
  double w;
  size_t i;

  if ( !get_number(wt, &w) || !get_vec(x, &a) || !get_vec(y, &b) || a.n != b.n )
    return FALSE;
  if ( !new_out(&o, a.n) )
    return FALSE;
  for(i = 0; i < a.n; i++)
  { double p = w * elem(&b, i), r;

    if ( !isfinite(p) || !isfinite(r = elem(&a, i) + p) )
    { free(o.buf);
      return FALSE;
    }
    set_elem(&o, i, r);
  }
  return unify_out(z, &o);
}

/* Values = QW/W where W > 0, else Q/N */
static foreign_t
fts_vector_weighted_mean(term_t qwt, term_t wt, term_t qt, term_t nt, term_t z)
{ vec qw, w, q;
  out_vec o;
  double n;
  size_t i;

  if ( !get_number(nt, &n) || n == 0.0 ||
       !get_vec(qwt, &qw) || !get_vec(wt, &w) || !get_vec(qt, &q) ||
       qw.n != w.n || w.n != q.n )
    return FALSE;
  if ( !new_out(&o, q.n) )
    return FALSE;
  for(i = 0; i < q.n; i++)
  { double wi = elem(&w, i);
    double r = (wi > 0) ? elem(&qw, i) / wi : elem(&q, i) / n;

    if ( !isfinite(r) )
    { free(o.buf);
      return FALSE;
    }
    set_elem(&o, i, r);
  }
  return unify_out(z, &o);
}

#define MODULE "float_vectors"

install_t
install_float_vectors(void)
{ FUNCTOR_fts1 = PL_new_functor(PL_new_atom("fts"), 1);
  PL_register_foreign_in_module(MODULE, "fts_vector_length", 2, fts_vector_length, 0);
  PL_register_foreign_in_module(MODULE, "fts_vector_binop", 4, fts_vector_binop, 0);
  PL_register_foreign_in_module(MODULE, "fts_vector_scale", 4, fts_vector_scale, 0);
  PL_register_foreign_in_module(MODULE, "fts_vector_add_scaled", 4, fts_vector_add_scaled, 0);
  PL_register_foreign_in_module(MODULE, "fts_vector_weighted_mean", 5,
				fts_vector_weighted_mean, 0);
}
