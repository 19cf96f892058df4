:- module(dfrl_aggregation,
          [ dfrl_method/1,              % ?Method
            aggregate_tables/3,         % +Method, +Tables, -Table
            aggregate_fold/5,           % +Method, +Acc0, +Shape, +Table, -Acc
            aggregate_finish/3,         % +Method, +Acc, -Table
            aggregate_fits/2,           % +Acc, +Shape
            item_shape/2,               % +Item, -Shape
            method_applies_to/2,        % +Method, +Carried
            check_method_applies/2,     % +Method, +Carried
            fold_hook/3,                % +Acc, +Method, -Hook
            method_call/3,              % :Goal, +Hook, -Result
            same_shape/2,               % +Shape0, +Shape
            item_floats/2               % +Item, -ListItem
          ]).
:- use_module('../platform_errors', [message_text/2, abbreviated/2]).
:- use_module(dfrl_safety, []).           % its entries in the platform's sandbox
%   The element-wise list maths were defined here first; they are
%   float_vectors.pl's now, and still exported from here.
:- reexport('../float_vectors',
            [ add_lists/3, mul_lists/3, max_lists/3, scale_list/3,
              add_scaled/4, weighted_mean/5 ]).
:- use_module('../float_vectors',
              [ vector_add/3, vector_mul/3, vector_max/3, vector_divide/3,
                vector_times/3, vector_add_scaled/4, vector_weighted_mean/5,
                vector_floats/2, vector_length/2, packed_vector/1 ]).
:- autoload(library(apply), [foldl/4]).
:- autoload(library(lists), [member/2]).
:- autoload(library(error), [must_be/2]).

/** <module> The dFRL agent's aggregation methods

How the tables (or parameter vectors) of a round become one, for the
dFRL agent (dfrl_agent.pl). An aggregation method is the clauses of five
multifile hooks of this module, aggregate_init/3, aggregate_step/4,
aggregate_final/3, method_uses_visits/1 and method_applies/2: the
aggregate acc(Shape, A) of a round is started from the first table by
aggregate_init/3, folded with each next table by aggregate_step/4, after
a check that the table has the aggregate's shape, and finished by
aggregate_final/3 into the table written back.

Built in: `average` (element-wise mean), `max` (element-wise maximum)
and `visit_average` (mean weighted by how often each state-action pair
was visited; pairs nobody visited get the plain mean), defined at the
end of this file on the element-wise vector maths of float_vectors.pl
(its list versions, add_lists/3 etc., are exported here too).

## Tables and parameters

An agent carries either Q-tables (`tables`: its robots are tabular
learners, or, in a grid federation, learners of any kind, a function
learner's table being its Q-function on the state grid, written back
by distillation: robots/grid_view.py) or parameter vectors (`params`:
function learners, e.g. DQN).
A method applies to what it declares with method_applies/2; a method
that declares nothing applies to tables only (every method written
before parameters existed). Of the built-ins only `average` applies to
parameters, as FedAvg: the mean weighted by the samples each learner
has learnt from, sum(w_i * x_i) / sum(w_i) (the plain mean if no
learner has learnt from any sample yet). `max` and `visit_average` are
refused for parameters by check_method_applies/2, when the agent is
created or the method is switched: the element-wise maximum of weights
of different networks is no network, and parameters have no visit
counts.

In params mode the hooks receive params(Layout, Samples, Values) (the
aggregate's shape is layout(Layout), checked the same way) and the
aggregate finishes into params(Layout, Values).

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
    method_uses_visits/1,       % ?Method
    method_applies/2,           % ?Method, ?Carried
    method_takes_vectors/1.     % ?Method

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

%!  method_applies(?Method, ?Carried) is nondet.
%
%   Hook: Method aggregates what an agent carries, Carried `tables`
%   (qtable/2 or qtable_visits/3 items) or `params` (params/3 items). A
%   method without a clause of this hook applies to tables only. E.g. a
%   method for both:
%
%   ```
%   dfrl_aggregation:method_applies(trimmed_mean, tables).
%   dfrl_aggregation:method_applies(trimmed_mean, params).
%   ```

%!  method_takes_vectors(?Method) is nondet.
%
%   Hook: Method's hooks take the values of a table (and its visit
%   counts, and a parameter vector) as vectors of float_vectors.pl,
%   a list or packed, and work on them with that module's operations
%   (vector_add/3, ...). The built-in methods do: the agent carries
%   tables packed, and their maths then runs on the packed form. Every
%   other method's hooks receive lists (item_floats/2), as they always
%   have.

%!  method_applies_to(+Method, +Carried) is semidet.
%
%   Method may aggregate Carried (`tables` or `params`): it says so with
%   method_applies/2, or says nothing and Carried is `tables`.

method_applies_to(Method, Carried) :-
    (   method_applies(Method, _)
    ->  method_applies(Method, Carried),
        !
    ;   Carried == tables
    ).

%!  check_method_applies(+Method, +Carried) is det.
%
%   As method_applies_to/2, or throw a domain error that names Method,
%   what it cannot aggregate and which methods can.
%
%   @error domain_error(params_method, Method) if Method does not apply
%   to parameter vectors (function learners).
%   @error domain_error(table_method, Method) if it does not apply to
%   Q-tables.

check_method_applies(Method, Carried) :-
    must_be(atom, Method),
    must_be(oneof([tables, params]), Carried),
    (   method_applies_to(Method, Carried)
    ->  true
    ;   findall(M, ( dfrl_method(M), method_applies_to(M, Carried) ), Ms),
        atomic_list_concat(Ms, ', ', Fit),
        refused_because(Method, Carried, Why),
        carried_words(Carried, Formal, What),
        format(string(Msg), "aggregation method ~q does not apply to ~w~w; \c
                             methods that do: ~w", [Method, What, Why, Fit]),
        throw(error(domain_error(Formal, Method), context(_, Msg)))
    ).

carried_words(params, params_method,
              'parameter vectors (an agent of function learners carries params)').
carried_words(tables, table_method, 'Q-tables (an agent of tabular learners carries tables)').

refused_because(max, params, Why) :-
    !,
    Why = ': the element-wise maximum of the weights of different networks is no network'.
refused_because(visit_average, params, Why) :-
    !,
    Why = ': parameters have no visit counts (use average, weighted by samples: FedAvg)'.
refused_because(_, _, '').

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
    item_shape(T, Shape),
    aggregate_fold(Method, none, Shape, T, A0),
    foldl([X, A1, A2]>>(item_shape(X, S), aggregate_fold(Method, A1, S, X, A2)), Ts, A0, A),
    aggregate_finish(Method, A, Table).

%!  item_shape(+Item, -Shape) is det.
%
%   Shape is the shape of what a robot gave: Shape of qtable(Shape, _)
%   and qtable_visits(Shape, _, _), layout(Layout) of params(Layout, _, _).

item_shape(params(Layout, _, _), layout(Layout)) :- !.
item_shape(Item, Shape) :-
    arg(1, Item, Shape).

%!  aggregate_fold(+Method, +Acc0, +Shape, +Table, -Acc) is semidet.
%
%   Acc is the aggregate Acc0 with Table, of shape Shape, folded in by
%   Method's hooks: started by aggregate_init/3 if Acc0 is `none`, else
%   stepped by aggregate_step/4. Fails or throws as the hook does.

aggregate_fold(Method, none, Shape, Table0, acc(Shape, A)) :-
    !,
    method_item(Method, Table0, Table),
    aggregate_init(Method, Table, A).
aggregate_fold(Method, acc(Shape0, A0), _Shape, Table0, acc(Shape0, A)) :-
    method_item(Method, Table0, Table),
    aggregate_step(Method, A0, Table, A).

%   What Method's hooks receive: the item as it is if the method takes
%   vectors (method_takes_vectors/1), else with every vector a list.
method_item(Method, Item0, Item) :-
    (   method_takes_vectors(Method)
    ->  Item = Item0
    ;   item_floats(Item0, Item)
    ).

%!  item_floats(+Item, -ListItem) is det.
%
%   ListItem is Item (qtable/2, qtable_visits/3 or params/3) with its
%   values (and visit counts) as lists of floats, whether they were
%   lists or packed (float_vectors.pl).

item_floats(qtable(S, V0), qtable(S, V)) :-
    !,
    vector_floats(V0, V).
item_floats(qtable_visits(S, V0, W0), qtable_visits(S, V, W)) :-
    !,
    vector_floats(V0, V),
    vector_floats(W0, W).
item_floats(params(L, N, V0), params(L, N, V)) :-
    !,
    vector_floats(V0, V).
item_floats(Item, Item).

%!  aggregate_finish(+Method, +Acc, -Table) is semidet.
%
%   Table is qtable(Shape, Values), the aggregate Acc finished by
%   Method's aggregate_final/3 (params(Layout, Values) for an aggregate of
%   parameters, shape layout(Layout)); `none` if nothing was aggregated.
%   Fails if aggregate_final/3 fails.
%
%   @error type_error(float_vector, Culprit) if Values is not a vector
%   (a list of numbers, or packed); Culprit is Values abbreviated.
%   @error domain_error(aggregate_size(N), Len) if Values has Len
%   elements where Shape (or Layout) holds N.

aggregate_finish(_, none, none) :- !.
aggregate_finish(Method, acc(layout(Layout), A), params(Layout, Values)) :-
    !,
    aggregate_final(Method, A, Values),
    check_finished(layout(Layout), Values).
aggregate_finish(Method, acc(Shape, A), qtable(Shape, Values)) :-
    aggregate_final(Method, A, Values),
    check_finished(Shape, Values).

%   check_finished(+Shape, +Values): Values is a vector of the number of
%   elements Shape holds (a shape not of integers or blocks is not sized).
check_finished(Shape, Values) :-
    (   is_vector(Values)
    ->  true
    ;   abbreviated(Values, Culprit),
        throw(error(type_error(float_vector, Culprit), _))
    ),
    (   shape_size(Shape, N)
    ->  vector_length(Values, Len),
        (   Len =:= N
        ->  true
        ;   throw(error(domain_error(aggregate_size(N), Len), _))
        )
    ;   true
    ).

is_vector(V) :-
    (   packed_vector(V)
    ->  true
    ;   is_list(V),
        forall(member(X, V), number(X))
    ).

shape_size(layout(Layout), N) :-
    !,
    is_list(Layout),
    foldl([_-Dims, N0, N1]>>(dims_size(Dims, P), N1 is N0 + P), Layout, 0, N).
shape_size(Dims, N) :-
    dims_size(Dims, N).

dims_size(Dims, N) :-
    is_list(Dims),
    foldl([D, P0, P]>>(integer(D), D >= 0, P is P0*D), Dims, 1, N).

%!  aggregate_fits(+Acc, +Shape) is det.
%
%   A table of Shape may be folded into the aggregate Acc: Acc is `none`
%   or has that shape.
%
%   @error domain_error(table_shape(Shape0), Shape), see same_shape/2.
%   @error domain_error(param_layout(Layout0), Layout) for parameters of
%   another layout than the aggregate's.

aggregate_fits(none, _) :- !.
aggregate_fits(acc(layout(L0), _), Shape) :-
    !,
    (   Shape == layout(L0)
    ->  true
    ;   Shape = layout(L)
    ->  throw(error(domain_error(param_layout(L0), L), _))
    ;   throw(error(domain_error(param_layout(L0), Shape), _))
    ).
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
		 *      BUILT-IN METHODS	*
		 *******************************/

method_takes_vectors(average).
method_takes_vectors(max).
method_takes_vectors(visit_average).

method_applies(average, tables).
method_applies(average, params).
aggregate_init(average, Item, Acc) :-
    average_init(Item, Acc).
aggregate_step(average, Acc0, Item, Acc) :-
    average_step(Item, Acc0, Acc).
aggregate_final(average, Acc, Mean) :-
    average_final(Acc, Mean).

%   (one clause per hook for `average`, the item's or aggregate's functor
%   picks the case: first-argument indexing leaves no choice point)
average_init(qtable(_, V), sum(V, 1)).
average_init(params(_, W, V), Acc) :-
    fedavg_init(W, V, Acc).

average_step(qtable(_, V), sum(A0, N0), sum(A, N)) :-
    vector_add(A0, V, A),
    N is N0 + 1.
average_step(params(_, W, V), Acc0, Acc) :-
    fedavg_step(Acc0, W, V, Acc).

average_final(sum(A, N), Mean) :-
    vector_divide(A, N, Mean).
average_final(fedavg(_, S, T), Mean) :-
    vector_divide(S, T, Mean).

%   FedAvg: fedavg(weighted, Sum of w*x, Sum of w) once some learner has
%   learnt from samples (a learner with none then weighs nothing);
%   fedavg(plain, Sum of x, Count) while none has (the plain mean).
fedavg_init(W, V, Acc) :-
    must_be(nonneg, W),
    (   W > 0
    ->  vector_times(V, W, WV),
        Acc = fedavg(weighted, WV, W)
    ;   Acc = fedavg(plain, V, 1)
    ).

fedavg_step(fedavg(Mode, S0, T0), W, V, Acc) :-
    must_be(nonneg, W),
    (   W =:= 0
    ->  (   Mode == plain
        ->  vector_add(S0, V, S),
            T is T0 + 1,
            Acc = fedavg(plain, S, T)
        ;   Acc = fedavg(weighted, S0, T0)
        )
    ;   Mode == plain
    ->  vector_times(V, W, WV),
        Acc = fedavg(weighted, WV, W)
    ;   vector_add_scaled(S0, W, V, S),
        T is T0 + W,
        Acc = fedavg(weighted, S, T)
    ).

aggregate_init(max, qtable(_, V), max(V)).
aggregate_step(max, max(A0), qtable(_, V), max(A)) :-
    vector_max(A0, V, A).
aggregate_final(max, max(A), A).

method_uses_visits(visit_average).
aggregate_init(visit_average, qtable_visits(_, Q, W), wsum(QW, W, Q, 1)) :-
    vector_mul(Q, W, QW).
aggregate_step(visit_average, wsum(QW0, W0, Q0, N0), qtable_visits(_, Q, W),
               wsum(QW, W1, Q1, N)) :-
    vector_mul(Q, W, QWi),
    vector_add(QW0, QWi, QW),
    vector_add(W0, W, W1),
    vector_add(Q0, Q, Q1),
    N is N0 + 1.
aggregate_final(visit_average, wsum(QW, W, Q, N), Values) :-
    vector_weighted_mean(QW, W, Q, N, Values).
