:- module(dfrl_aggregation,
          [ dfrl_method/1,              % ?Method
            aggregate_tables/3,         % +Method, +Tables, -Table
            aggregate_fold/5,           % +Method, +Acc0, +Shape, +Table, -Acc
            aggregate_finish/3,         % +Method, +Acc, -Table
            aggregate_fits/2,           % +Acc, +Shape
            fold_hook/3,                % +Acc, +Method, -Hook
            method_call/3,              % :Goal, +Hook, -Result
            same_shape/2,               % +Shape0, +Shape
            add_lists/3,                % +Xs, +Ys, -Sums
            mul_lists/3,                % +Xs, +Ys, -Products
            max_lists/3,                % +Xs, +Ys, -Maxima
            scale_list/3,               % +Xs, +N, -Quotients
            weighted_mean/5             % +QWs, +Ws, +Qs, +N, -Values
          ]).
:- use_module('../platform_errors', [message_text/2]).
:- autoload(library(apply), [foldl/4]).
:- autoload(library(lists), [member/2]).

/** <module> The dFRL agent's aggregation methods

How the tables of a round become one, for the dFRL agent
(dfrl_agent.pl). An aggregation method is the clauses of four multifile
hooks of this module, aggregate_init/3, aggregate_step/4,
aggregate_final/3 and method_uses_visits/1: the aggregate acc(Shape, A)
of a round is started from the first table by aggregate_init/3, folded
with each next table by aggregate_step/4, after a check that the table
has the aggregate's shape, and finished by aggregate_final/3 into the
table written back.

Built in: `average` (element-wise mean), `max` (element-wise maximum)
and `visit_average` (mean weighted by how often each state-action pair
was visited; pairs nobody visited get the plain mean), defined at the
end of this file on the element-wise list maths exported here.

## Adding a method

A new method is plain Prolog: clauses of the hooks, loaded into running
nodes with load_program_at/3 (a peer's program may add clauses to these
hooks only, see code_safety.pl) and selected with the agent's control
command method(Name). Example (a complete one, the median, is in
examples/median_method.pl beside this file):

```
:- multifile dfrl_aggregation:aggregate_init/3,
             dfrl_aggregation:aggregate_step/4,
             dfrl_aggregation:aggregate_final/3.
dfrl_aggregation:aggregate_init(min, qtable(_, V), V).
dfrl_aggregation:aggregate_step(min, Acc0, qtable(_, V), Acc) :-
    maplist([A,B,C]>>(C is min(A,B)), Acc0, V, Acc).
dfrl_aggregation:aggregate_final(min, Acc, Acc).
```

A method that needs visit counts also declares
dfrl_aggregation:method_uses_visits(Name); its hooks then receive
qtable_visits(Shape, Values, Visits). A method may build on another by
calling its hooks, e.g. dfrl_aggregation:aggregate_step(average, A0, T, A).

A method is user code: method_call/3 runs one of its steps and says, as
text, how it failed or what it threw, so that the agent can abort the
round and log why instead of crashing.
*/

:- multifile
    aggregate_init/3,           % +Method, +Table, -Acc
    aggregate_step/4,           % +Method, +Acc0, +Table, -Acc
    aggregate_final/3,          % +Method, +Acc, -Values
    method_uses_visits/1.       % ?Method

:- meta_predicate method_call(0, +, -).

%!  aggregate_init(+Method, +Table, -Acc) is semidet.
%
%   Hook of an aggregation method: start the aggregate Acc of a round
%   from the first robot's Table, qtable(Shape, Values) (Values a flat
%   list of floats), or qtable_visits(Shape, Values, Visits) when
%   method_uses_visits(Method). Defining a clause for a new Method name
%   defines the method (see dfrl_method/1). A hook that fails or throws
%   aborts the round: logged with an `error`, no table written.

%!  aggregate_step(+Method, +Acc0, +Table, -Acc) is semidet.
%
%   Hook of an aggregation method: fold the Table of the next robot of
%   the forward pass into the aggregate Acc0 (same shapes are checked
%   before). Failing or throwing aborts the round, as for
%   aggregate_init/3.

%!  aggregate_final(+Method, +Acc, -Values) is semidet.
%
%   Hook of an aggregation method: the table Values (a flat list, the
%   shape of the first table) that the agent writes back to every robot
%   it visited in the round, from the aggregate Acc.

%!  method_uses_visits(?Method) is nondet.
%
%   Hook: Method's aggregate_init/3 and aggregate_step/4 receive
%   qtable_visits(Shape, Values, Visits), the tables with their visit
%   counts (e.g. visit_average).

%!  dfrl_method(?Method) is nondet.
%
%   Method is an aggregation method known on this node: it has a clause
%   of aggregate_init/3.

dfrl_method(M) :-
    (   nonvar(M)
    ->  clause(aggregate_init(M, _, _), _), !
    ;   setof(X, B^Y^Z^clause(aggregate_init(X, Y, Z), B), Ms),
        member(M, Ms)
    ).

%!  aggregate_tables(+Method, +Tables, -Table) is det.
%
%   Aggregate a list of qtable(Shape, Values) (or qtable_visits/3 for
%   methods that use visits) in one go, as the agent does over a round.
%   Mobile code may call it (see code_safety.pl).

aggregate_tables(Method, [T|Ts], Table) :-
    arg(1, T, Shape),
    aggregate_fold(Method, none, Shape, T, A0),
    foldl([X, A1, A2]>>(arg(1, X, S), aggregate_fold(Method, A1, S, X, A2)), Ts, A0, A),
    aggregate_finish(Method, A, Table).

%!  aggregate_fold(+Method, +Acc0, +Shape, +Table, -Acc) is semidet.
%
%   Acc is the aggregate Acc0 with Table, of shape Shape, folded in by
%   Method's hooks: started by aggregate_init/3 if Acc0 is `none`, else
%   stepped by aggregate_step/4. Fails or throws as the hook does.

aggregate_fold(Method, none, Shape, Table, acc(Shape, A)) :-
    !,
    aggregate_init(Method, Table, A).
aggregate_fold(Method, acc(Shape0, A0), _Shape, Table, acc(Shape0, A)) :-
    aggregate_step(Method, A0, Table, A).

%!  aggregate_finish(+Method, +Acc, -Table) is semidet.
%
%   Table is qtable(Shape, Values), the aggregate Acc finished by
%   Method's aggregate_final/3; `none` if nothing was aggregated.

aggregate_finish(_, none, none) :- !.
aggregate_finish(Method, acc(Shape, A), qtable(Shape, Values)) :-
    aggregate_final(Method, A, Values).

%!  aggregate_fits(+Acc, +Shape) is det.
%
%   A table of Shape may be folded into the aggregate Acc: Acc is `none`
%   or has that shape.
%
%   @error domain_error(table_shape(Shape0), Shape), see same_shape/2.

aggregate_fits(none, _) :- !.
aggregate_fits(acc(Shape0, _), Shape) :-
    same_shape(Shape0, Shape).

%!  fold_hook(+Acc, +Method, -Hook) is det.
%
%   Hook names the hook aggregate_fold/5 calls on Acc, for messages:
%   aggregate_init(Method) or aggregate_step(Method).

fold_hook(none, Method, aggregate_init(Method)) :- !.
fold_hook(_, Method, aggregate_step(Method)).

%!  method_call(:Goal, +Hook, -Result) is det.
%
%   Run Goal, a step of an aggregation method (Hook names it, e.g.
%   aggregate_final(median)), once. Result is `ok` when Goal succeeded,
%   else error(Text), Text saying how Hook failed or what it threw.

method_call(Goal, Hook, Result) :-
    catch(( Goal -> R = true ; R = failed ), E, R = thrown(E)),
    (   R == true
    ->  Result = ok
    ;   R == failed
    ->  format(string(Error), "~q failed", [Hook]),
        Result = error(Error)
    ;   R = thrown(E),
        message_text(E, Text),
        format(string(Error), "~q raised: ~w", [Hook, Text]),
        Result = error(Error)
    ).

%!  same_shape(+Shape0, +Shape) is det.
%
%   Shape, the shape of a robot's table, is Shape0, the shape of the
%   round's aggregate.
%
%   @error domain_error(table_shape(Shape0), Shape) if it is not.

same_shape(S, S) :- !.
same_shape(S, S1) :-
    throw(error(domain_error(table_shape(S), S1), _)).

		 /*******************************
		 *      ELEMENT-WISE MATHS	*
		 *******************************/

%!  add_lists(+Xs, +Ys, -Sums) is semidet.
%!  mul_lists(+Xs, +Ys, -Products) is semidet.
%!  max_lists(+Xs, +Ys, -Maxima) is semidet.
%
%   Element-wise sum, product and maximum of two lists of numbers of one
%   length (fails on lists of different lengths).

%!  scale_list(+Xs, +N, -Quotients) is det.
%
%   Each element of Xs divided by N.

%!  weighted_mean(+QWs, +Ws, +Qs, +N, -Values) is semidet.
%
%   Element-wise QW/W where the weight W is positive, else Q/N: the
%   visit-weighted mean of N tables from the sums of Q*W (QWs), of the
%   weights (Ws) and of Q (Qs). Fails on lists of different lengths.

%   The element-wise helpers are compiled with the optimise flag, which
%   turns is/2 into virtual-machine arithmetic: 2.5 times faster on
%   20,000-element lists. The flag is restored after them.
:- dynamic saved_optimise/1.
:- current_prolog_flag(optimise, O),
   assertz(saved_optimise(O)),
   set_prolog_flag(optimise, true).

add_lists([], [], []).
add_lists([A|As], [B|Bs], [C|Cs]) :- C is A + B, add_lists(As, Bs, Cs).

mul_lists([], [], []).
mul_lists([A|As], [B|Bs], [C|Cs]) :- C is A * B, mul_lists(As, Bs, Cs).

max_lists([], [], []).
max_lists([A|As], [B|Bs], [C|Cs]) :- C is max(A, B), max_lists(As, Bs, Cs).

scale_list([], _, []).
scale_list([A|As], N, [C|Cs]) :- C is A / N, scale_list(As, N, Cs).

weighted_mean([], [], [], _, []).
weighted_mean([QW|QWs], [W|Ws], [Q|Qs], N, [V|Vs]) :-
    (   W > 0 -> V is QW / W ; V is Q / N ),
    weighted_mean(QWs, Ws, Qs, N, Vs).

:- retract(saved_optimise(O)),
   set_prolog_flag(optimise, O).

		 /*******************************
		 *      BUILT-IN METHODS	*
		 *******************************/

aggregate_init(average, qtable(_, V), sum(V, 1)).
aggregate_step(average, sum(A0, N0), qtable(_, V), sum(A, N)) :-
    add_lists(A0, V, A),
    N is N0 + 1.
aggregate_final(average, sum(A, N), Mean) :-
    scale_list(A, N, Mean).

aggregate_init(max, qtable(_, V), max(V)).
aggregate_step(max, max(A0), qtable(_, V), max(A)) :-
    max_lists(A0, V, A).
aggregate_final(max, max(A), A).

method_uses_visits(visit_average).
aggregate_init(visit_average, qtable_visits(_, Q, W), wsum(QW, W, Q, 1)) :-
    mul_lists(Q, W, QW).
aggregate_step(visit_average, wsum(QW0, W0, Q0, N0), qtable_visits(_, Q, W),
               wsum(QW, W1, Q1, N)) :-
    mul_lists(Q, W, QWi),
    add_lists(QW0, QWi, QW),
    add_lists(W0, W, W1),
    add_lists(Q0, Q, Q1),
    N is N0 + 1.
aggregate_final(visit_average, wsum(QW, W, Q, N), Values) :-
    weighted_mean(QW, W, Q, N, Values).
