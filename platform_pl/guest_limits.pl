:- module(guest_limits,
          [ guest_module_init/1,        % +Module
            guest_hazard/1,             % ?Name/Arity
            guest_text_size/4,          % +Term, +Quoted, +Max, -Chars
            guest_eval/2,               % -Value, +Expression
            guest_static_refusal/2,     % +Goal, -Why
            guest_context/1,            % +Module
            guest_goal/1,               % :Goal
            guest_closure/3, guest_closure/4, guest_closure/5,
            guest_closure/6, guest_closure/7, guest_closure/8,
            guest_closure/9,
            % the checked versions, under the names guests write
            (is)/2, (<)/2, (>)/2, (=<)/2, (>=)/2, (=:=)/2, (=\=)/2,
            tab/1, tab/2,
            format/1, format/2, format/3,
            write/1, print/1, writeln/1, writeq/1, write_canonical/1,
            write_term/2, write/2, writeq/2, print/2, writeln/2,
            write_canonical/2, write_term/3,
            atom_concat/3, atomic_list_concat/2, atomic_list_concat/3,
            string_concat/3, upcase_atom/2, downcase_atom/2, string_upper/2,
            string_lower/2, term_to_atom/2, term_string/2, term_string/3,
            write_length/3, text_concat/3,
            atom_number/2, number_codes/2, number_chars/2, atom_length/2,
            atom_string/2, number_string/2, atom_codes/2, atom_chars/2,
            string_codes/2, string_chars/2, string_to_atom/2,
            nth_integer_root_and_remainder/4, divmod/4,
            sum_list/2, sumlist/2, max_list/2, min_list/2,
            aggregate_all/3, must_be/2, is_of_type/2
          ]).
:- use_module(library(prolog_format), [format_spec/2]).
:- use_module(library(lists), []).
:- use_module(library(aggregate), []).
:- use_module(library(error), []).

/** <module> Sizes of C-level work checked before guest code does it

SWI-Prolog 9.0.4 handles signals only between Prolog calls, so a single
call into C that builds a huge atom (`format(atom(A), "~*c", [N, 0'x])`,
atomic_list_concat/2 of many copies of one long atom) or a huge integer
(`X is 7^400000000`, GMP works outside the Prolog stacks) cannot be
stopped by agent_bounds.pl's monitor, and 9.0.4 has no
max_integer_size flag. This module holds *checked versions* of those
predicates, under the names guest code writes: each estimates the size
of its result from its arguments and, over a limit, raises instead of
calling the built-in:

  | what                          | limit (flag)                           | default |
  |-------------------------------|----------------------------------------|---------|
  | characters of text one call makes (atoms, strings, output of one write or format) | dfrl_guest_text_limit | 8,388,608 |
  | bits of an integer (result or operand of a non-linear operation) | dfrl_guest_integer_bits | 8,388,608 (1 MiB) |

Arithmetic is evaluated bottom up: each node of the expression gets its
operands as numbers, and `*`, `^`, `**`, `<<`, `>>` (negative shift),
`powm`, `/`, `//`, `div`, `mod`, `rem`, `gcd`, `lcm`, rationals are
checked on their operands' bits before the node is evaluated. Text is
estimated from the arguments (atom and string lengths, digits of
integers, quoted text at 5 characters a character, a term's written
size walked with a cut-off at the limit); format/1,2,3 adds the column,
padding, repeat and precision arguments of its directives (`~Nc`, `~*c`,
`~t~N|`, `~N+`, `~Ne`, `~Nd`, `~Nn`). Library predicates that evaluate
the caller's data (sum_list/2, max_list/2, aggregate_all/3 with sum/max/
min, must_be/2 of between(L,H)) are here too.

How guest code reaches them (guest_module_init/1): an agent's module
inherits from this one (its base module, above `user`), so meta-calls
from it (`call(is, X, E)`, maplist/N, yall lambdas, findall/forall,
foldl) resolve here; and it imports each of them, because a clause
asserted into a module that does not define a system predicate itself
binds its calls to `system` at once (pl-comp.c's lookupBodyProcedure),
whatever the module inherits. sandbox_policy.pl refuses the other ways
to the built-ins: an explicit module (`system:is(X, E)`,
`call(lists:is, X, E)`, `apply:maplist(is, ...)`). Trusted modules (the
platform, the dFRL agent) never see this module and pay nothing.

Over a limit, inside a bounded call (agent_bounds.pl) the call is stopped
with '$dfrl_bound'(text_size(Limit)) or '$dfrl_bound'(integer_size(Limit))
(the agent is removed, its source told); elsewhere the error is
resource_error(guest_text) or resource_error(guest_integer).
*/

:- set_prolog_flag(optimise, true).     % this file: arithmetic compiled inline
:- create_prolog_flag(dfrl_guest_text_limit, 8388608, [type(integer), keep(true)]).
:- create_prolog_flag(dfrl_guest_integer_bits, 8388608, [type(integer), keep(true)]).

:- redefine_system_predicate(is(_,_)).
:- redefine_system_predicate(<(_,_)).
:- redefine_system_predicate(>(_,_)).
:- redefine_system_predicate(=<(_,_)).
:- redefine_system_predicate(>=(_,_)).
:- redefine_system_predicate(=:=(_,_)).
:- redefine_system_predicate(=\=(_,_)).
:- redefine_system_predicate(tab(_)).
:- redefine_system_predicate(tab(_,_)).
:- redefine_system_predicate(format(_)).
:- redefine_system_predicate(format(_,_)).
:- redefine_system_predicate(format(_,_,_)).
:- redefine_system_predicate(write(_)).
:- redefine_system_predicate(print(_)).
:- redefine_system_predicate(writeln(_)).
:- redefine_system_predicate(writeq(_)).
:- redefine_system_predicate(write_canonical(_)).
:- redefine_system_predicate(write_term(_,_)).
:- redefine_system_predicate(write(_,_)).
:- redefine_system_predicate(writeq(_,_)).
:- redefine_system_predicate(print(_,_)).
:- redefine_system_predicate(writeln(_,_)).
:- redefine_system_predicate(write_canonical(_,_)).
:- redefine_system_predicate(write_term(_,_,_)).
:- redefine_system_predicate(atom_concat(_,_,_)).
:- redefine_system_predicate(atomic_list_concat(_,_)).
:- redefine_system_predicate(atomic_list_concat(_,_,_)).
:- redefine_system_predicate(string_concat(_,_,_)).
:- redefine_system_predicate(upcase_atom(_,_)).
:- redefine_system_predicate(downcase_atom(_,_)).
:- redefine_system_predicate(string_upper(_,_)).
:- redefine_system_predicate(string_lower(_,_)).
:- redefine_system_predicate(term_to_atom(_,_)).
:- redefine_system_predicate(term_string(_,_)).
:- redefine_system_predicate(term_string(_,_,_)).
:- redefine_system_predicate(write_length(_,_,_)).
:- redefine_system_predicate(text_concat(_,_,_)).
:- redefine_system_predicate(atom_number(_,_)).
:- redefine_system_predicate(number_codes(_,_)).
:- redefine_system_predicate(number_chars(_,_)).
:- redefine_system_predicate(atom_length(_,_)).
:- redefine_system_predicate(atom_string(_,_)).
:- redefine_system_predicate(number_string(_,_)).
:- redefine_system_predicate(atom_codes(_,_)).
:- redefine_system_predicate(atom_chars(_,_)).
:- redefine_system_predicate(string_codes(_,_)).
:- redefine_system_predicate(string_chars(_,_)).
:- redefine_system_predicate(string_to_atom(_,_)).
:- redefine_system_predicate(nth_integer_root_and_remainder(_,_,_,_)).
:- redefine_system_predicate(divmod(_,_,_,_)).

:- meta_predicate
    format(+, :),
    format(+, +, :),
    write_term(?, :),
    write_term(+, ?, :),
    aggregate_all(?, 0, -),
    guest_goal(0).

%!  guest_hazard(?PI) is nondet.
%
%   PI (Name/Arity) is a predicate this module holds a checked version of.
%   (The ISO built-ins among them, is/2 and write/1 for instance, are not
%   in the module's export list, whatever its header says: SWI-Prolog
%   leaves them out. They are imported by name.)

guest_hazard(is/2).
guest_hazard((<)/2).
guest_hazard((>)/2).
guest_hazard((=<)/2).
guest_hazard((>=)/2).
guest_hazard((=:=)/2).
guest_hazard((=\=)/2).
guest_hazard(tab/1).
guest_hazard(tab/2).
guest_hazard(format/1).
guest_hazard(format/2).
guest_hazard(format/3).
guest_hazard(write/1).
guest_hazard(print/1).
guest_hazard(writeln/1).
guest_hazard(writeq/1).
guest_hazard(write_canonical/1).
guest_hazard(write_term/2).
guest_hazard(write/2).
guest_hazard(writeq/2).
guest_hazard(print/2).
guest_hazard(writeln/2).
guest_hazard(write_canonical/2).
guest_hazard(write_term/3).
guest_hazard(atom_concat/3).
guest_hazard(atomic_list_concat/2).
guest_hazard(atomic_list_concat/3).
guest_hazard(string_concat/3).
guest_hazard(upcase_atom/2).
guest_hazard(downcase_atom/2).
guest_hazard(string_upper/2).
guest_hazard(string_lower/2).
guest_hazard(term_to_atom/2).
guest_hazard(term_string/2).
guest_hazard(term_string/3).
guest_hazard(write_length/3).
guest_hazard(text_concat/3).
guest_hazard(atom_number/2).
guest_hazard(number_codes/2).
guest_hazard(number_chars/2).
guest_hazard(atom_length/2).
guest_hazard(atom_string/2).
guest_hazard(number_string/2).
guest_hazard(atom_codes/2).
guest_hazard(atom_chars/2).
guest_hazard(string_codes/2).
guest_hazard(string_chars/2).
guest_hazard(string_to_atom/2).
guest_hazard(nth_integer_root_and_remainder/4).
guest_hazard(divmod/4).
guest_hazard(sum_list/2).
guest_hazard(sumlist/2).
guest_hazard(max_list/2).
guest_hazard(min_list/2).
guest_hazard(aggregate_all/3).
guest_hazard(must_be/2).
guest_hazard(is_of_type/2).

%   Importing a predicate a module does not export is what
%   guest_module_init/1 means to do: no warning.
:- multifile user:message_hook/3.

user:message_hook(import_private(_, guest_limits:_), warning, _).

%   This module's own arithmetic is the built-in's (its exported is/2
%   and comparisons are the checked ones, for guests).
goal_expansion(G, system:G) :-
    prolog_load_context(source, File),
    module_property(guest_limits, file(File)),
    compound(G),
    compound_name_arity(G, F, 2),
    memberchk(F, [is, <, >, =<, >=, =:=, =\=]).

%!  guest_module_init(+Module) is det.
%
%   Make Module, an agent's module, resolve the checked versions: this
%   module becomes its base module (it inherits `user` through it) and
%   each checked predicate is imported, so that clauses asserted into
%   Module afterwards call them (predicate_property/2 would report them
%   imported already, through the base module: they are imported
%   unconditionally, which is a no-op the second time). Call it before
%   any clause is asserted into Module.

guest_module_init(M) :-
    must_be_atom(M),
    set_module(M:base(guest_limits)),
    forall(( guest_hazard(PI), \+ library_hazard(PI) ),
           catch(@(import(guest_limits:PI), M), E,
                 print_message(warning, E))).

%   Library predicates: a clause calling them binds the call at run time,
%   through the base module; no import needed (each import costs every
%   walk over the module's predicates, e.g. agent_bounds' module_size,
%   about 1 us).
library_hazard(sum_list/2).
library_hazard(sumlist/2).
library_hazard(max_list/2).
library_hazard(min_list/2).
library_hazard(aggregate_all/3).
library_hazard(must_be/2).
library_hazard(is_of_type/2).

must_be_atom(M) :-
    (   atom(M) -> true ; throw(error(type_error(atom, M), _)) ).

%!  guest_context(+Module) is semidet.
%
%   Module is one where guest code runs or is checked: a call written
%   there without a module reaches this module's checked versions (an
%   agent's module), or is code under check (code_safety.pl's scratch
%   module, where a program's clauses are checked too).

guest_context(guest_limits).
guest_context(code_safety_scratch).
guest_context(M) :-
    atom(M),
    sub_atom(M, 0, _, _, 'dfrl_agent@').

%!  guest_static_refusal(+Goal, -Why) is semidet.
%
%   Goal, a call of one of the checked predicates as written in guest
%   code, is over a limit whatever happens before it: an expression, a
%   format's arguments or a tab/1 count that are known (ground) when the
%   code is checked. Why is an atom that says which size and limit.

guest_static_refusal(G, Why) :-
    callable(G),
    catch(setup_call_cleanup(b_setval(guest_limits_static, true),
                             static_check(G),
                             b_setval(guest_limits_static, false)),
          error(resource_error(R), context(Culprit, size(Size, Max))),
          true),
    nonvar(R),
    (   R == guest_integer
    ->  system:format(atom(Why), 'integer of ~D bits at ~q (over dfrl_guest_integer_bits, ~D)',
                      [Size, Culprit, Max])
    ;   system:format(atom(Why), 'text of ~D characters by ~q (over dfrl_guest_text_limit, ~D)',
                      [Size, Culprit, Max])
    ).

static_check(G) :-
    functor(G, Name, Arity),
    (   Name == is, Arity == 2
    ->  arg(2, G, E), static_eval(E)
    ;   Arity == 2, memberchk(Name, [<, >, =<, >=, =:=, =\=])
    ->  arg(1, G, A), arg(2, G, B), static_eval(A), static_eval(B)
    ;   Name == tab
    ->  arg(Arity, G, N), static_eval(N),
        (   ground(N) -> guest_eval(V, N), check_text(tab/Arity, V) ; true )
    ;   Name == format
    ->  static_format(G, Arity)
    ;   true
    ).

%   Only ground expressions are evaluated at check time (their errors,
%   other than sizes, are the run's).
static_eval(E) :-
    (   ground(E)
    ->  catch(guest_eval(_, E), error(Formal, Context),
              (   Formal = resource_error(_)
              ->  throw(error(Formal, Context))
              ;   true
              ))
    ;   true
    ).

static_format(G, Arity) :-
    (   Arity =:= 1 -> arg(1, G, F), Args = [] ; true ),
    (   Arity =:= 2 -> arg(1, G, F), arg(2, G, Args) ; true ),
    (   Arity =:= 3 -> arg(2, G, F), arg(3, G, Args) ; true ),
    (   ground(F), catch(format_spec(F, Spec), _, fail)
    ->  text_limit(Max),
        forall(member(escape(number(N), _, _), Spec),
               (   N > Max -> throw(error(resource_error(guest_text),
                                          context(format(F), size(N, Max))))
               ;   true
               )),
        (   ground(Args)
        ->  format_size(format/Arity, F, Args)
        ;   true
        )
    ;   true
    ).

member(X, [X|_]).
member(X, [_|T]) :- member(X, T).

		 /*******************************
		 *            LIMITS		*
		 *******************************/

text_limit(Max) :- current_prolog_flag(dfrl_guest_text_limit, Max).
bits_limit(Max) :- current_prolog_flag(dfrl_guest_integer_bits, Max).

over_text(Culprit, Size, Max) :-
    over(text_size(Max), guest_text, Culprit, Size, Max).
over_bits(Culprit, Size, Max) :-
    over(integer_size(Max), guest_integer, Culprit, Size, Max).

%   Inside a bounded call the agent is stopped (and its source told);
%   elsewhere (and when checking code before it is installed) a
%   resource error.
over(Kind, Resource, Culprit, Size, Max) :-
    (   \+ nb_current(guest_limits_static, true),
        catch(agent_bounds:current_call_(_, _, _, _), _, fail)
    ->  throw('$dfrl_bound'(Kind))
    ;   throw(error(resource_error(Resource), context(Culprit, size(Size, Max))))
    ).

check_text(Culprit, Size) :-
    text_limit(Max),
    (   Size > Max -> over_text(Culprit, Size, Max) ; true ).

		 /*******************************
		 *          ARITHMETIC		*
		 *******************************/

X is E :-
    (   number(E)
    ->  X = E
    ;   cheap(E, 1024, _)
    ->  system:is(X, E)
    ;   guest_eval(V, E),
        X = V
    ).
A < B :- guest_eval(X, A), guest_eval(Y, B), system:(X < Y).
A > B :- guest_eval(X, A), guest_eval(Y, B), system:(X > Y).
A =< B :- guest_eval(X, A), guest_eval(Y, B), system:(X =< Y).
A >= B :- guest_eval(X, A), guest_eval(Y, B), system:(X >= Y).
A =:= B :- guest_eval(X, A), guest_eval(Y, B), system:(X =:= Y).
A =\= B :- guest_eval(X, A), guest_eval(Y, B), system:(X =\= Y).

%!  guest_eval(-Value, +Expression) is det.
%
%   As is/2, evaluated node by node; a node that would make or work on an
%   integer over dfrl_guest_integer_bits raises before GMP is called.

guest_eval(V, E) :-
    (   number(E)
    ->  V = E
    ;   cheap(E, 1024, _)                    % at most 65,536 bits
    ->  system:is(V, E)
    ;   compound(E),
        \+ E = [_|_],
        compound_name_arity(E, F, A),
        A > 0
    ->  compound_name_arity(E1, F, A),
        eval_args(F, 1, A, E, E1, Vs),
        check_op(F, Vs, E1),
        system:is(V, E1)
    ;   system:is(V, E)
    ).

%   cheap(+Expr, +Room0, -Room): Expr has no power or shift, its
%   integers fit in 60 bits and it has fewer than Room0 leaves: no value
%   of it has more than 64 bits a leaf (a product of n such numbers has
%   at most 64n bits: 65,536 bits, under any sensible
%   dfrl_guest_integer_bits; a smaller limit is checked node by node for
%   expressions of more than a few leaves only). The common case (N + 1,
%   X * 2.0 + Y), evaluated at once.
cheap(E, R0, R) :-
    (   integer(E)
    ->  E > -1152921504606846976, E < 1152921504606846976,
        R is R0 - 1, R > 0
    ;   float(E)
    ->  R is R0 - 1, R > 0
    ;   atom(E)
    ->  R is R0 - 1, R > 0
    ;   compound(E),
        compound_name_arity(E, F, A),
        \+ risky(F),
        A > 0, A =< 3,
        \+ E = [_|_]
    ->  cheap_args(A, E, R0, R)
    ).

cheap_args(0, _, R, R) :- !.
cheap_args(I, E, R0, R) :-
    arg(I, E, X),
    cheap(X, R0, R1),
    I1 is I - 1,
    cheap_args(I1, E, R1, R).

risky(^).
risky(**).
risky(<<).
risky(>>).
risky(powm).
risky(roundtoward).
risky(rdiv).
risky(rational).
risky(rationalize).

eval_args(F, I, A, E, E1, Vs) :-
    (   I > A
    ->  Vs = []
    ;   arg(I, E, X),
        (   F == roundtoward, I == 2
        ->  Y = X
        ;   guest_eval(Y, X)
        ),
        arg(I, E1, Y),
        Vs = [Y|Vs1],
        I1 is I + 1,
        eval_args(F, I1, A, E, E1, Vs1)
    ).

%   bits(+Number, -Bits): of an integer's magnitude, of a rational's
%   numerator plus denominator; 0 for a float.
bits(X, B) :-
    (   integer(X)
    ->  (   X =:= 0 -> B = 0 ; B is msb(abs(X)) + 1 )
    ;   rational(X, N, D)
    ->  bits(N, BN), bits(D, BD), B is BN + BD
    ;   B = 0
    ).

check_op(F, Vs, E) :-
    bits_limit(Max),
    (   op_bits(F, Vs, Bits)
    ->  (   Bits > Max -> over_bits(E, Bits, Max) ; true )
    ;   true
    ).

%   op_bits(+Op, +Operands, -Bits): the bits the operation makes or
%   works on, for the operations that cost more than linear time or make
%   more bits than their operands have.
op_bits(*, [A, B], Bits) :- bits(A, BA), bits(B, BB), Bits is BA + BB.
op_bits(^, [A, B], Bits) :- power_bits(A, B, Bits).
op_bits(**, [A, B], Bits) :- power_bits(A, B, Bits).
op_bits(<<, [A, B], Bits) :- integer(B), bits(A, BA), Bits is BA + max(0, B).
op_bits(>>, [A, B], Bits) :- integer(B), bits(A, BA), Bits is BA + max(0, -B).
op_bits(powm, [B, E, M], Bits) :-
    bits(B, BB), bits(E, BE), bits(M, BM),
    Bits is max(BB, max(BM, BE * BM // 8192)).
op_bits(lcm, [A, B], Bits) :- bits(A, BA), bits(B, BB), Bits is BA + BB.
op_bits(F, Vs, Bits) :-
    memberchk(F, [/, //, div, mod, rem, gcd, rdiv, rational, rationalize,
                  +, -, min, max, cmpflags, truncate, integer]),
    max_bits(Vs, 0, Bits).

max_bits([], B, B).
max_bits([V|Vs], B0, B) :-
    bits(V, B1),
    B2 is max(B0, B1),
    max_bits(Vs, B2, B).

%   Bits of A^B for an integer exponent: |A| =< 1 makes no bits.
power_bits(A, B, Bits) :-
    (   integer(B), ( integer(A) ; rational(A) )
    ->  bits(A, BA),
        (   integer(A), abs(A) =< 1
        ->  Bits = BA
        ;   Bits is BA * max(1, abs(B))
        )
    ;   Bits = 0
    ).

divmod(A, B, Q, R) :-
    int_operands(divmod/4, [A, B]),
    system:divmod(A, B, Q, R).

nth_integer_root_and_remainder(N, I, Root, Rem) :-
    int_operands(nth_integer_root_and_remainder/4, [I]),
    system:nth_integer_root_and_remainder(N, I, Root, Rem).

int_operands(Culprit, Vs) :-
    bits_limit(Max),
    max_bits(Vs, 0, Bits),
    (   Bits > Max -> over_bits(Culprit, Bits, Max) ; true ).

		 /*******************************
		 *      LIBRARY ARITHMETIC	*
		 *******************************/

sum_list(Xs, Sum) :- sum_(Xs, 0, Sum).
sumlist(Xs, Sum) :- sum_(Xs, 0, Sum).

sum_(V, _, _) :- var(V), !, throw(error(instantiation_error, _)).
sum_([], S, S).
sum_([X|Xs], S0, S) :-
    (   number(X), number(S0)
    ->  system:is(S1, S0 + X)                % adding numbers: linear
    ;   guest_eval(S1, S0 + X)
    ),
    sum_(Xs, S1, S).

max_list([H|T], Max) :- foldl_eval(T, max, H, Max0), guest_eval(Max, Max0).
min_list([H|T], Min) :- foldl_eval(T, min, H, Min0), guest_eval(Min, Min0).

foldl_eval([], _, V, V).
foldl_eval([X|Xs], Op, V0, V) :-
    E =.. [Op, V0, X],
    (   number(X), number(V0)
    ->  system:is(V1, E)                     % max, min of numbers
    ;   guest_eval(V1, E)
    ),
    foldl_eval(Xs, Op, V1, V).

%   aggregate_all/3: sum, max and min evaluate the caller's template;
%   the rest are the library's.
aggregate_all(Spec, M:Goal, Result) :-
    (   nonvar(Spec), Spec = sum(X)
    ->  system:findall(X, M:Goal, Xs), sum_(Xs, 0, Result)
    ;   nonvar(Spec), Spec = max(X), var_or_number(Result)
    ->  system:findall(X, M:Goal, Xs), Xs \== [], max_list(Xs, Result)
    ;   nonvar(Spec), Spec = min(X), var_or_number(Result)
    ->  system:findall(X, M:Goal, Xs), Xs \== [], min_list(Xs, Result)
    ;   nonvar(Spec), functor(Spec, F, _), memberchk(F, [sum, max, min])
    ->  evaluated_template(Spec),
        aggregate:aggregate_all(Spec, M:Goal, Result)
    ;   aggregate:aggregate_all(Spec, M:Goal, Result)
    ).

var_or_number(X) :- ( var(X) -> true ; number(X) ).

%   max(X, W), min(X, W): X is evaluated by the library; only numbers
%   (or a variable, bound by the goal: checked by the library's is/2 on
%   the values the goal gave, which this module cannot see) pass.
evaluated_template(Spec) :-
    arg(1, Spec, X),
    (   ( number(X) ; var(X) ) -> true
    ;   throw(error(type_error(number, X), _))
    ).

%   must_be/2, is_of_type/2: between(L, H) compares with the bounds,
%   which must be numbers, not expressions.
must_be(Type, X) :-
    checked_type(Type),
    error:must_be(Type, X).
is_of_type(Type, X) :-
    checked_type(Type),
    error:is_of_type(Type, X).

checked_type(Type) :-
    (   nonvar(Type), Type = between(L, H)
    ->  (   number(L), number(H) -> true
        ;   throw(error(type_error(number, between(L, H)), _))
        )
    ;   true
    ).

		 /*******************************
		 *             TEXT		*
		 *******************************/

%!  guest_text_size(+Term, +Quoted, +Max, -Chars) is det.
%
%   Chars is at least the number of characters of Term written (quoted
%   if Quoted is true), or some number over Max once the walk passes Max
%   (a term with shared subterms is written in full: its written size can
%   be exponential in its size on the stacks). Cyclic terms count as over.

guest_text_size(T, Quoted, Max, Size) :-
    (   cyclic_term(T)
    ->  Size is Max + 1
    ;   catch(size(T, Quoted, Max, 0, Size), over(Size), true)
    ).

size(T, Q, Max, S0, S) :-
    (   var(T) -> S1 is S0 + 24
    ;   atom(T) -> system:atom_length(T, L), chars(Q, L, C), S1 is S0 + C
    ;   string(T) -> string_length(T, L), chars(Q, L, C), S1 is S0 + C
    ;   integer(T) -> bits(T, B), S1 is S0 + B * 31 // 100 + 2
    ;   number(T) -> bits(T, B), S1 is S0 + 32 + B * 31 // 100
    ;   compound(T)
    ->  compound_name_arity(T, N, A),
        system:atom_length(N, NL),
        chars(Q, NL, C),
        S2 is S0 + C + 2 + 3 * A,
        args_size(1, A, T, Q, Max, S2, S1)
    ;   S1 is S0 + 64                       % blobs: <stream>(0x...)
    ),
    (   S1 > Max -> throw(over(S1)) ; S = S1 ).

args_size(I, A, T, Q, Max, S0, S) :-
    (   I > A
    ->  S = S0
    ;   arg(I, T, X),
        size(X, Q, Max, S0, S1),
        I1 is I + 1,
        args_size(I1, A, T, Q, Max, S1, S)
    ).

chars(true, L, C) :- !, C is 5 * L + 2.
chars(_, L, L).

text_size(T, Q, S) :-
    text_limit(Max),
    guest_text_size(T, Q, Max, S).

check_terms(Culprit, Q, Terms) :-
    text_limit(Max),
    terms_size(Terms, Q, Max, 0, S),
    (   S > Max -> over_text(Culprit, S, Max) ; true ).

terms_size([], _, _, S, S).
terms_size([T|Ts], Q, Max, S0, S) :-
    (   S0 > Max
    ->  S = S0
    ;   Max1 is Max - S0,
        guest_text_size(T, Q, Max1, S1),
        S2 is S0 + S1,
        terms_size(Ts, Q, Max, S2, S)
    ).

%   Text conversions: the result is about as long as the input, unless
%   the input is an integer (its digits) or the output is a list.
convert(Culprit, In) :-
    (   nonvar(In)
    ->  check_terms(Culprit, false, [In])
    ;   true
    ).

atom_concat(A, B, C) :-
    (   nonvar(A), nonvar(B) -> check_terms(atom_concat/3, false, [A, B]) ; true ),
    system:atom_concat(A, B, C).
string_concat(A, B, C) :-
    (   nonvar(A), nonvar(B) -> check_terms(string_concat/3, false, [A, B]) ; true ),
    system:string_concat(A, B, C).
text_concat(A, B, C) :-
    (   nonvar(A), nonvar(B) -> check_terms(text_concat/3, false, [A, B]) ; true ),
    system:text_concat(A, B, C).
atomic_list_concat(L, A) :-
    list_text(atomic_list_concat/2, L, '', _),
    system:atomic_list_concat(L, A).
atomic_list_concat(L, Sep, A) :-
    (   nonvar(Sep) -> list_text(atomic_list_concat/3, L, Sep, _) ; true ),
    system:atomic_list_concat(L, Sep, A).

%   A proper list whose elements are all bound: its joined length is
%   checked (sum of elements and separators); a partial list is the
%   built-in's split mode or an error.
list_text(Culprit, L, Sep, joins) :-
    is_list(L),
    !,
    text_limit(Max),
    (   atomic(Sep) -> size(Sep, false, Max, 0, SL) ; SL = 0 ),
    catch(join_size(L, SL, Max, 0, S), over(S), true),
    (   S > Max -> over_text(Culprit, S, Max) ; true ).
list_text(_, _, _, split).

join_size([], _, _, S, S).
join_size([X|Xs], SL, Max, S0, S) :-
    (   var(X) -> S1 = S0
    ;   size(X, false, Max, S0, S2), S1 is S2 + SL
    ),
    (   S1 > Max -> throw(over(S1)) ; true ),
    join_size(Xs, SL, Max, S1, S).

upcase_atom(A, U) :- convert(upcase_atom/2, A), system:upcase_atom(A, U).
downcase_atom(A, U) :- convert(downcase_atom/2, A), system:downcase_atom(A, U).
string_upper(A, U) :- convert(string_upper/2, A), system:string_upper(A, U).
string_lower(A, U) :- convert(string_lower/2, A), system:string_lower(A, U).
atom_number(A, N) :- ( var(A) -> convert(atom_number/2, N) ; true ), system:atom_number(A, N).
number_codes(N, C) :- convert(number_codes/2, N), system:number_codes(N, C).
number_chars(N, C) :- convert(number_chars/2, N), system:number_chars(N, C).
atom_length(A, L) :- convert(atom_length/2, A), system:atom_length(A, L).
atom_string(A, S) :- convert(atom_string/2, A), system:atom_string(A, S).
number_string(N, S) :- convert(number_string/2, N), system:number_string(N, S).
atom_codes(A, C) :- convert(atom_codes/2, A), system:atom_codes(A, C).
atom_chars(A, C) :- convert(atom_chars/2, A), system:atom_chars(A, C).
string_codes(S, C) :- convert(string_codes/2, S), system:string_codes(S, C).
string_chars(S, C) :- convert(string_chars/2, S), system:string_chars(S, C).
string_to_atom(S, A) :- convert(string_to_atom/2, S), system:string_to_atom(S, A).
term_to_atom(T, A) :-
    (   var(A) -> check_terms(term_to_atom/2, true, [T]) ; true ),
    system:term_to_atom(T, A).
term_string(T, S) :-
    (   var(S) -> check_terms(term_string/2, true, [T]) ; true ),
    system:term_string(T, S).
term_string(T, S, Opts) :-
    (   var(S) -> check_terms(term_string/3, true, [T]) ; true ),
    system:term_string(T, S, Opts).
%   write_length/3 writes to nowhere, but a term with shared subterms
%   is written in full, in C: exponential time no signal stops.
write_length(T, L, Opts) :-
    check_terms(write_length/3, true, [T]),
    system:write_length(T, L, Opts).

		 /*******************************
		 *            OUTPUT		*
		 *******************************/

write(T) :- check_terms(write/1, false, [T]), system:write(T).
print(T) :- check_terms(print/1, true, [T]), system:print(T).
writeln(T) :- check_terms(writeln/1, false, [T]), system:writeln(T).
writeq(T) :- check_terms(writeq/1, true, [T]), system:writeq(T).
write_canonical(T) :- check_terms(write_canonical/1, true, [T]), system:write_canonical(T).
write_term(T, Opts) :- check_terms(write_term/2, true, [T]), system:write_term(T, Opts).
write(S, T) :- check_terms(write/2, false, [T]), system:write(S, T).
writeq(S, T) :- check_terms(writeq/2, true, [T]), system:writeq(S, T).
print(S, T) :- check_terms(print/2, true, [T]), system:print(S, T).
writeln(S, T) :- check_terms(writeln/2, false, [T]), system:writeln(S, T).
write_canonical(S, T) :- check_terms(write_canonical/2, true, [T]), system:write_canonical(S, T).
write_term(S, T, Opts) :- check_terms(write_term/3, true, [T]), system:write_term(S, T, Opts).

tab(N) :-
    guest_eval(V, N),
    check_text(tab/1, V),
    system:tab(V).
tab(S, N) :-
    guest_eval(V, N),
    check_text(tab/2, V),
    system:tab(S, V).

format(F) :-
    format_size(format/1, F, []),
    system:format(F).
format(F, M:Args) :-
    format_size(format/2, F, Args),
    system:format(F, M:Args).
format(Out, F, M:Args) :-
    format_size(format/3, F, Args),
    system:format(Out, F, M:Args).

%   The output of one format call, estimated from its directives and
%   arguments, within dfrl_guest_text_limit. A format that does not
%   parse is left to the built-in (which raises).
format_size(Culprit, F, Args0) :-
    (   is_list(Args0) -> Args = Args0 ; Args = [Args0] ),
    (   parsed_format(F, Spec)
    ->  text_limit(Max),
        catch(spec_size(Spec, Args, Max, 0, 0, Size), over(Size), true),
        (   Size > Max -> over_text(Culprit, Size, Max) ; true )
    ;   true
    ).

%   parsed_format(+Format, -Spec): format_spec/2 (a parser in Prolog,
%   some 20 us) once per format text; the last 1,000 are kept.
:- dynamic spec_/3.                     % Hash, Format, Spec

parsed_format(F, Spec) :-
    (   atomic(F)
    ->  term_hash(F, H),
        (   spec_(H, F0, Spec0), F0 == F
        ->  Spec = Spec0
        ;   catch(format_spec(F, Spec), _, fail),
            (   predicate_property(spec_(_, _, _), number_of_clauses(N)),
                N >= 1000
            ->  retractall(spec_(_, _, _))
            ;   true
            ),
            assertz(spec_(H, F, Spec))
        )
    ;   catch(format_spec(F, Spec), _, fail)
    ).

%   spec_size(+Spec, +Args, +Max, +Column, +Size0, -Size): Column is the
%   sum of the column stops so far (a ~N| or ~N+ can pad up to there).
spec_size([], _, _, _, S, S).
spec_size([D|Ds], Args0, Max, Col0, S0, S) :-
    (   D = text(T)
    ->  string_length(T, L), S1 is S0 + L, Args = Args0, Col = Col0
    ;   D = escape(Num0, _, Dir)
    ->  numeric(Num0, Args0, Args1, Num),
        directive(Dir, Num, Args1, Args, Max, Col0, Col, Add),
        S1 is S0 + Add
    ;   S1 = S0, Args = Args0, Col = Col0
    ),
    (   S1 > Max -> throw(over(S1)) ; true ),
    spec_size(Ds, Args, Max, Col, S1, S).

numeric(star, [N|Args], Args, N) :- !,
    (   integer(N) -> true ; throw(error(type_error(integer, N), _)) ).
numeric(number(N), Args, Args, N) :- !.
numeric(_, Args, Args, default).

num(default, D, D) :- !.
num(N, _, N).

%   directive(+Char, +Numeric, +Args0, -Args, +Max, +Col0, -Col, -Chars)
directive(Dir, Num, Args0, Args, Max, Col0, Col0, Add) :-
    memberchk(Dir, [w, p, q, a, k, s]),
    !,
    take(Args0, T, Args),
    (   memberchk(Dir, [p, q, k]) -> Q = true ; Q = false ),
    guest_text_size(T, Q, Max, Add0),
    num(Num, 0, N),
    Add is Add0 + N.
directive(Dir, Num, Args0, Args, _, Col0, Col0, Add) :-
    memberchk(Dir, [d, 'D', r, 'R']),
    !,
    take(Args0, T, Args),
    (   number(T) -> bits(T, B) ; B = 64 ),
    num(Num, 0, N),
    (   memberchk(Dir, [r, 'R']) -> Add is B + 2 ; Add is B * 31 // 100 * 4 // 3 + N + 4 ).
directive(Dir, Num, Args0, Args, _, Col0, Col0, Add) :-
    memberchk(Dir, [e, f, g]),
    !,
    take(Args0, T, Args),
    (   number(T) -> bits(T, B) ; B = 64 ),
    num(Num, 6, N),
    Add is N + B * 31 // 100 + 330.
directive(c, Num, Args0, Args, _, Col0, Col0, Add) :- !,
    take(Args0, _, Args),
    num(Num, 1, Add).
directive(n, Num, Args, Args, _, Col0, Col0, Add) :- !,
    num(Num, 1, Add).
directive(i, _, Args0, Args, _, Col0, Col0, 0) :- !,
    take(Args0, _, Args).
directive('|', Num, Args, Args, _, Col0, Col, Add) :- !,
    num(Num, 0, N),
    Col is max(Col0, N),
    Add = N.
directive(+, Num, Args, Args, _, Col0, Col, Add) :- !,
    num(Num, 8, N),
    Col is Col0 + N,
    Add = Col.
directive(t, _, Args, Args, _, Col, Col, 0) :- !.
directive(@, _, Args0, Args, _, Col, Col, 0) :- !,   % the goal's own output is checked
    take(Args0, _, Args).
directive(_, Num, Args, Args, _, Col, Col, Add) :-
    num(Num, 0, Add).

take([], _, []).
take([A|As], A, As).

		 /*******************************
		 *      PROGRAMS FROM PEERS	*
		 *******************************/

%   A program a peer sent is loaded into `user` (codeload.pl, source
%   dfrl_program://Id), which does not inherit from this module. While it
%   loads, its goals are rewritten: a call of a checked predicate without
%   a module becomes guest_limits:Goal (SWI-Prolog's expansion applies
%   this inside findall/forall goals and closures, maplist(is, ...)
%   included), and a goal or closure that is a variable in a meta-argument
%   (call(G), findall(X, G, L), maplist(C, L)) is wrapped in
%   guest_goal/1 or guest_closure/N, which rewrite it the same way when
%   it is called. Locally loaded programs are not touched.

:- multifile system:goal_expansion/2.

system:goal_expansion(G0, G) :-
    prolog_load_context(source, Source),
    atom(Source),
    sub_atom(Source, 0, _, _, 'dfrl_program://'),
    \+ prolog_load_context(module, guest_limits),
    program_goal(G0, G).

program_goal(G0, G) :-
    callable(G0),
    \+ G0 = _:_,
    b_setval(guest_limits_compiling, true),
    rewrite(G0, G1),
    b_setval(guest_limits_compiling, false),
    wrap_meta(G1, G),
    G \== G0.

%   Variables in meta-arguments of a goal (not of a control construct:
%   the expansion visits their parts) are wrapped.
wrap_meta(G0, G) :-
    (   \+ G0 = _:_,
        \+ control(G0),
        catch(predicate_property(user:G0, meta_predicate(Spec)), _, fail)
    ->  G0 =.. [Name|Args0],
        Spec =.. [_|Specs],
        wrap_vars(Specs, Args0, Args, _),
        G =.. [Name|Args]
    ;   G = G0
    ).

load_module(M) :-
    (   prolog_load_context(module, M0) -> M = M0 ; M = user ).

control((_,_)).
control((_;_)).
control((_->_)).
control((_*->_)).
control(\+ _).

wrap_vars([], [], [], _).
wrap_vars([S|Ss], [A0|As0], [A|As], Changed) :-
    (   var(A0), S == 0
    ->  A = guest_limits:guest_goal(A0), Changed = true
    ;   var(A0), integer(S), S > 0, S =< 7
    ->  load_module(M),
        A = guest_limits:guest_closure(M, A0), Changed = true
    ;   A = A0
    ),
    wrap_vars(Ss, As0, As, Changed).

%!  guest_goal(:Goal) is nondet.
%
%   Call Goal with its calls of checked predicates (at any depth of
%   control constructs, meta-arguments and yall lambdas) rewritten to
%   this module's versions.

guest_goal(M:G0) :-
    rewrite(G0, G),
    call(M:G).

%!  guest_closure(+Module, +Closure, ?A1, ...) is nondet.
%
%   As call/N of Module:Closure, rewritten as guest_goal/1 does. Module
%   is an argument, not a meta-argument, so that the load's expansion
%   leaves Closure alone (library(yall) would compile a lambda in it).

guest_closure(M, C, A1) :- closure_call(M, C, [A1]).
guest_closure(M, C, A1, A2) :- closure_call(M, C, [A1,A2]).
guest_closure(M, C, A1, A2, A3) :- closure_call(M, C, [A1,A2,A3]).
guest_closure(M, C, A1, A2, A3, A4) :- closure_call(M, C, [A1,A2,A3,A4]).
guest_closure(M, C, A1, A2, A3, A4, A5) :- closure_call(M, C, [A1,A2,A3,A4,A5]).
guest_closure(M, C, A1, A2, A3, A4, A5, A6) :- closure_call(M, C, [A1,A2,A3,A4,A5,A6]).
guest_closure(M, C, A1, A2, A3, A4, A5, A6, A7) :- closure_call(M, C, [A1,A2,A3,A4,A5,A6,A7]).

%   The closure is rewritten once for a run of calls with the same
%   closure (maplist/N over a table calls it once an element): the last
%   one and its rewriting are kept in a backtrackable global variable
%   of the thread, which shares the closure's variables, so == tells it.
closure_call(M, C, Extra) :-
    (   nb_current(guest_limits_closure, C0-C1),
        C0 == C
    ->  true
    ;   length(Extra, N),
        (   nonvar(C), \+ C = _:_
        ->  rewrite_closure(N, C, C1)
        ;   C1 = C
        ),
        b_setval(guest_limits_closure, C-C1)
    ),
    closure_goal(C1, Extra, G),
    (   C1 = _:_ -> call(G) ; call(M:G) ).

closure_goal(C, Extra, G) :-
    (   var(C)
    ->  throw(error(instantiation_error, _))
    ;   C = Q:C1
    ->  closure_goal(C1, Extra, G1), G = Q:G1
    ;   C =.. L0,
        append_(L0, Extra, L),
        G =.. L
    ).

append_([], L, L).
append_([H|T], L, [H|R]) :- append_(T, L, R).

%   rewrite(+Goal0, -Goal): the run-time form of the expansion above.
rewrite(G0, G) :-
    (   var(G0)
    ->  G = G0
    ;   G0 = _:_
    ->  G = G0
    ;   G0 = (A0, B0) -> rewrite(A0, A), rewrite(B0, B), G = (A, B)
    ;   G0 = (A0 ; B0) -> rewrite(A0, A), rewrite(B0, B), G = (A ; B)
    ;   G0 = (A0 -> B0) -> rewrite(A0, A), rewrite(B0, B), G = (A -> B)
    ;   G0 = (A0 *-> B0) -> rewrite(A0, A), rewrite(B0, B), G = (A *-> B)
    ;   G0 = (\+ A0) -> rewrite(A0, A), G = (\+ A)
    ;   lambda(G0, G)
    ->  true
    ;   callable(G0),
        functor(G0, Name, Arity),
        guest_hazard(Name/Arity)
    ->  G = guest_limits:G0
    ;   callable(G0),
        catch(predicate_property(user:G0, meta_predicate(Spec)), _, fail)
    ->  G0 =.. [Name|Args0],
        Spec =.. [_|Specs],
        rewrite_args(Specs, Args0, Args),
        G =.. [Name|Args]
    ;   G = G0
    ).

rewrite_args([], [], []).
rewrite_args([S|Ss], [A0|As0], [A|As]) :-
    (   S == 0 -> rewrite(A0, A)
    ;   S == ^ -> rewrite_hat(A0, A)
    ;   integer(S), S > 0, nonvar(A0), \+ A0 = _:_
    ->  rewrite_closure(S, A0, A)
    ;   A = A0
    ),
    rewrite_args(Ss, As0, As).

rewrite_hat(G0, G) :-
    (   nonvar(G0), G0 = V^G1
    ->  rewrite_hat(G1, G2), G = V^G2
    ;   rewrite(G0, G)
    ).

%   A closure of N arguments: a checked predicate is qualified, a lambda
%   gets its body rewritten.
rewrite_closure(N, C0, C) :-
    (   lambda_closure(C0, C1)
    ->  (   nb_current(guest_limits_compiling, true)
        ->  load_module(M),
            C = guest_limits:guest_closure(M, C0)   % see below
        ;   C = C1
        )
    ;   callable(C0),
        functor(C0, Name, A0),
        A is A0 + N,
        guest_hazard(Name/A)
    ->  C = guest_limits:C0
    ;   C = C0
    ).

%   While a program loads, a lambda is wrapped whole rather than its
%   body rewritten: library(yall) compiles a lambda into a predicate of
%   its own and decides which variables it shares with the clause by
%   looking at the body, where it does not look inside Module:Goal (a
%   rewritten body lost a shared variable: max_visited.pl's N).
lambda_closure(Ps>>B0, Ps>>B) :- rewrite(B0, B).
lambda_closure(Free/L0, Free/L) :- nonvar(L0), lambda_closure(L0, L).
lambda_closure(\X^B0, \X^B) :- rewrite_hat(B0, B).

%   A lambda called with its arguments: >>(Params, Body, A1, ...).
lambda(G0, G) :-
    compound(G0),
    compound_name_arguments(G0, F, [P, B0|Rest]),
    memberchk(F, [>>, /]),
    (   F == (>>) -> rewrite(B0, B) ; nonvar(B0), lambda_closure(B0, B) ),
    compound_name_arguments(G, F, [P, B|Rest]).
